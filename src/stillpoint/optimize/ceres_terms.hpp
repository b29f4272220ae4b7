#pragma once
// Ceres building blocks of the back-end (used by bundle_adjustment.cpp and pose_graph.cpp; public
// so the tests can check them). A pose is stored as 7 doubles [qx qy qz qw tx ty tz] (T_cw) with
// the SE3Manifold below: Plus is the left update exp(delta) * T.
//
// Analytic Jacobians use the "lifted" convention: each cost function writes its derivative with
// respect to the 6-D tangent increment into the first 6 columns of the 7-column ambient Jacobian
// (last column zero), and PlusJacobian is [I6; 0], so Ceres' product J_ambient * PlusJacobian is
// exactly the tangent Jacobian.
#include <ceres/ceres.h>

#include <array>
#include <atomic>
#include <string>

#include "stillpoint/geometry/lie.hpp"
#include "stillpoint/optimize/residuals.hpp"

namespace sp::opt {

using PoseParams = std::array<double, 7>;

inline PoseParams to_params(const geo::SE3& T) {
  const Eigen::Quaterniond& q = T.quaternion();
  const Eigen::Vector3d& t = T.translation();
  return {q.x(), q.y(), q.z(), q.w(), t.x(), t.y(), t.z()};
}

inline geo::SE3 from_params(const double* p) {
  return geo::SE3(Eigen::Quaterniond(p[3], p[0], p[1], p[2]), Eigen::Vector3d(p[4], p[5], p[6]));
}

// "eigen" | "suite_sparse" (validated by the configs) to Ceres' sparse library enum; throws sp::Error
// for any other name.
ceres::SparseLinearAlgebraLibraryType sparse_library_type(const std::string& name);

class SE3Manifold final : public ceres::Manifold {
 public:
  [[nodiscard]] int AmbientSize() const override { return 7; }
  [[nodiscard]] int TangentSize() const override { return 6; }
  bool Plus(const double* x, const double* delta, double* x_plus_delta) const override;
  bool PlusJacobian(const double* x, double* jacobian) const override;
  bool Minus(const double* y, const double* x, double* y_minus_x) const override;
  bool MinusJacobian(const double* x, double* jacobian) const override;
};

// Reprojection of a point (3 params) in a keyframe (7 params); Dim 2 = monocular, 3 = stereo.
template <int Dim>
class ReprojectionCost final : public ceres::SizedCostFunction<Dim, 7, 3> {
 public:
  ReprojectionCost(const CameraModel& camera, const Eigen::Vector2d& uv, double u_right, double sqrt_info)
      : camera_(camera), uv_(uv), u_right_(Dim == 3 ? u_right : -1.0), sqrt_info_(sqrt_info) {}

  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    const double* pose = parameters[0];
    const Eigen::Quaterniond q(pose[3], pose[0], pose[1], pose[2]);
    const Eigen::Matrix3d R = q.normalized().toRotationMatrix();
    const Eigen::Vector3d t(pose[4], pose[5], pose[6]);
    const Eigen::Map<const Eigen::Vector3d> p_w(parameters[1]);
    const bool want_pose = jacobians != nullptr && jacobians[0] != nullptr;
    const bool want_point = jacobians != nullptr && jacobians[1] != nullptr;
    const Reprojection rep =
        evaluate_reprojection(camera_, R, t, p_w, uv_, u_right_, sqrt_info_, want_pose, want_point);
    // Behind the camera the residual is left at zero (with zero Jacobians): the point drops out of
    // this evaluation instead of failing the whole solve; the chi-square pass flags it later.
    for (int k = 0; k < Dim; ++k) residuals[k] = rep.residual[k];
    if (want_pose) {
      Eigen::Map<Eigen::Matrix<double, Dim, 7, Eigen::RowMajor>> J(jacobians[0]);
      J.template leftCols<6>() = rep.J_pose.template topRows<Dim>();
      J.col(6).setZero();
    }
    if (want_point) {
      Eigen::Map<Eigen::Matrix<double, Dim, 3, Eigen::RowMajor>> J(jacobians[1]);
      J = rep.J_point.template topRows<Dim>();
    }
    return true;
  }

 private:
  CameraModel camera_;
  Eigen::Vector2d uv_;
  double u_right_;
  double sqrt_info_;
};

// Pose-graph edge between two poses (7 params each), residual sqrt(w) log(T_ij^-1 T_iw T_jw^-1).
class PoseGraphCost final : public ceres::SizedCostFunction<6, 7, 7> {
 public:
  PoseGraphCost(const geo::SE3& T_ij, double sqrt_weight) : T_ij_(T_ij), sqrt_weight_(sqrt_weight) {}
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override;

 private:
  geo::SE3 T_ij_;
  double sqrt_weight_;
};

// Stops a Ceres solve (as a success, keeping the current state) once *flag becomes true.
class AbortCallback final : public ceres::IterationCallback {
 public:
  explicit AbortCallback(const std::atomic<bool>* flag) : flag_(flag) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& /*summary*/) override {
    if (flag_ != nullptr && flag_->load(std::memory_order_relaxed))
      return ceres::SOLVER_TERMINATE_SUCCESSFULLY;
    return ceres::SOLVER_CONTINUE;
  }

 private:
  const std::atomic<bool>* flag_;
};

}  // namespace sp::opt
