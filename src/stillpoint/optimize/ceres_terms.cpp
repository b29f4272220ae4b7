#include "stillpoint/optimize/ceres_terms.hpp"

#include "stillpoint/common/error.hpp"

namespace sp::opt {

ceres::SparseLinearAlgebraLibraryType sparse_library_type(const std::string& name) {
  if (name == "eigen") return ceres::EIGEN_SPARSE;
  if (name == "suite_sparse") return ceres::SUITE_SPARSE;
  throw Error("unknown sparse library '" + name + "' (eigen | suite_sparse)");
}

bool SE3Manifold::Plus(const double* x, const double* delta, double* x_plus_delta) const {
  const Eigen::Map<const geo::Vec6> d(delta);
  const PoseParams out = to_params(geo::SE3::exp(d) * from_params(x));
  std::copy(out.begin(), out.end(), x_plus_delta);
  return true;
}

bool SE3Manifold::PlusJacobian(const double* /*x*/, double* jacobian) const {
  Eigen::Map<Eigen::Matrix<double, 7, 6, Eigen::RowMajor>> J(jacobian);
  J.setZero();
  J.topRows<6>().setIdentity();
  return true;
}

bool SE3Manifold::Minus(const double* y, const double* x, double* y_minus_x) const {
  Eigen::Map<geo::Vec6> out(y_minus_x);
  out = (from_params(y) * from_params(x).inverse()).log();
  return true;
}

bool SE3Manifold::MinusJacobian(const double* /*x*/, double* jacobian) const {
  Eigen::Map<Eigen::Matrix<double, 6, 7, Eigen::RowMajor>> J(jacobian);
  J.setZero();
  J.leftCols<6>().setIdentity();
  return true;
}

bool PoseGraphCost::Evaluate(double const* const* parameters, double* residuals, double** jacobians) const {
  const geo::SE3 T_iw = from_params(parameters[0]);
  const geo::SE3 T_jw = from_params(parameters[1]);
  const bool want_i = jacobians != nullptr && jacobians[0] != nullptr;
  const bool want_j = jacobians != nullptr && jacobians[1] != nullptr;
  geo::Mat6 Ji, Jj;
  const geo::Vec6 r =
      pose_graph_residual(T_iw, T_jw, T_ij_, sqrt_weight_, want_i ? &Ji : nullptr, want_j ? &Jj : nullptr);
  Eigen::Map<geo::Vec6> out(residuals);
  out = r;
  if (want_i) {
    Eigen::Map<Eigen::Matrix<double, 6, 7, Eigen::RowMajor>> J(jacobians[0]);
    J.leftCols<6>() = Ji;
    J.col(6).setZero();
  }
  if (want_j) {
    Eigen::Map<Eigen::Matrix<double, 6, 7, Eigen::RowMajor>> J(jacobians[1]);
    J.leftCols<6>() = Jj;
    J.col(6).setZero();
  }
  return true;
}

}  // namespace sp::opt
