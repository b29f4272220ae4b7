#include "stillpoint/optimize/residuals.hpp"

namespace sp::opt {

geo::Vec6 pose_graph_residual(const geo::SE3& T_iw, const geo::SE3& T_jw, const geo::SE3& T_ij, double sqrt_w,
                              geo::Mat6* J_i, geo::Mat6* J_j) {
  const geo::SE3 T_ij_inv = T_ij.inverse();
  const geo::SE3 E = T_ij_inv * T_iw * T_jw.inverse();
  const geo::Vec6 r = E.log();
  if (J_i != nullptr || J_j != nullptr) {
    // exp(d) T_iw gives exp(Ad(T_ij^-1) d) E; (exp(d) T_jw)^-1 gives E exp(-d).
    if (J_i != nullptr) *J_i = sqrt_w * geo::se3_left_jacobian_inv(r) * T_ij_inv.adjoint();
    if (J_j != nullptr) *J_j = -sqrt_w * geo::se3_right_jacobian_inv(r);
  }
  return sqrt_w * r;
}

}  // namespace sp::opt
