#pragma once
// Residuals of the optimisation back-end with analytic Jacobians, shared by the hand-written pose
// solver and the Ceres cost functions.
//
// Perturbation convention (everywhere in sp::opt): poses are T_cw (camera-from-world) and are
// updated on the LEFT, T_cw <- exp(delta) * T_cw, delta = [rho; phi] as in geo::SE3::exp. All pose
// Jacobians below are derivatives with respect to that delta at delta = 0.
#include <Eigen/Core>
#include <cmath>

#include "stillpoint/geometry/lie.hpp"

namespace sp::opt {

// Pinhole model of undistorted keypoints; bf = baseline * fx gives the virtual right coordinate
// u_R = u - bf / z that ORB-SLAM uses for RGB-D ("stereo") observations.
struct CameraModel {
  double fx = 0, fy = 0, cx = 0, cy = 0;
  double bf = 0;  // pixels * metres
};

// (u, v, u_R) of a camera-frame point; the caller checks z > 0.
inline Eigen::Vector3d project_stereo(const CameraModel& cam, const Eigen::Vector3d& p_c) {
  const double iz = 1.0 / p_c.z();
  const double u = cam.fx * p_c.x() * iz + cam.cx;
  return {u, cam.fy * p_c.y() * iz + cam.cy, u - cam.bf * iz};
}

// d(u, v, u_R) / d p_c (the first two rows are the monocular projection Jacobian).
inline Eigen::Matrix3d projection_jacobian(const CameraModel& cam, const Eigen::Vector3d& p_c) {
  const double iz = 1.0 / p_c.z();
  const double iz2 = iz * iz;
  Eigen::Matrix3d J;
  J << cam.fx * iz, 0, -cam.fx * p_c.x() * iz2,  //
      0, cam.fy * iz, -cam.fy * p_c.y() * iz2,   //
      cam.fx * iz, 0, -cam.fx * p_c.x() * iz2 + cam.bf * iz2;
  return J;
}

// Weighted reprojection residual r = sqrt_info * (measured - projected) of a point p_w seen by the
// camera T_cw. Monocular when u_right < 0 (rows 0..1 used), stereo (u, v, u_R) otherwise. Optional
// Jacobians: J_pose w.r.t. the left increment of T_cw, J_point w.r.t. p_w (unused rows are zero).
// Returns the camera-frame depth z; when z <= 0 nothing else is meaningful.
struct Reprojection {
  Eigen::Vector3d residual = Eigen::Vector3d::Zero();
  Eigen::Matrix<double, 3, 6> J_pose = Eigen::Matrix<double, 3, 6>::Zero();
  Eigen::Matrix3d J_point = Eigen::Matrix3d::Zero();
  double depth = 0;
  int dim = 2;
  // Squared weighted error, the chi-square statistic compared with chi2_mono / chi2_stereo.
  [[nodiscard]] double chi2() const { return residual.head(dim).squaredNorm(); }
  // The chi-square outlier test of ORB-SLAM's optimisers: behind the camera, or chi2 above the
  // threshold of its dimension (2: monocular, 3: with the virtual right coordinate).
  [[nodiscard]] bool is_outlier(double chi2_mono, double chi2_stereo) const {
    return depth <= 0 || chi2() > (dim == 2 ? chi2_mono : chi2_stereo);
  }
};

inline Reprojection evaluate_reprojection(const CameraModel& cam, const Eigen::Matrix3d& R_cw,
                                          const Eigen::Vector3d& t_cw, const Eigen::Vector3d& p_w,
                                          const Eigen::Vector2d& uv, double u_right, double sqrt_info,
                                          bool with_pose_jacobian, bool with_point_jacobian) {
  Reprojection out;
  const Eigen::Vector3d p_c = R_cw * p_w + t_cw;
  out.depth = p_c.z();
  out.dim = u_right < 0 ? 2 : 3;
  if (out.depth <= 0) return out;
  const Eigen::Vector3d proj = project_stereo(cam, p_c);
  out.residual.x() = sqrt_info * (uv.x() - proj.x());
  out.residual.y() = sqrt_info * (uv.y() - proj.y());
  out.residual.z() = out.dim == 3 ? sqrt_info * (u_right - proj.z()) : 0.0;
  if (!with_pose_jacobian && !with_point_jacobian) return out;
  Eigen::Matrix3d Jp = -sqrt_info * projection_jacobian(cam, p_c);
  if (out.dim == 2) Jp.row(2).setZero();
  if (with_pose_jacobian) {
    // d p_c / d delta = [I, -hat(p_c)] for exp(delta) * T_cw.
    out.J_pose.leftCols<3>() = Jp;
    out.J_pose.rightCols<3>() = -Jp * geo::hat(p_c);
  }
  if (with_point_jacobian) out.J_point = Jp * R_cw;
  return out;
}

// Pose-graph edge residual r = sqrt_w * log(T_ij^-1 * T_iw * T_jw^-1) with Jacobians w.r.t. the
// left increments of T_iw and T_jw.
geo::Vec6 pose_graph_residual(const geo::SE3& T_iw, const geo::SE3& T_jw, const geo::SE3& T_ij, double sqrt_w,
                              geo::Mat6* J_i, geo::Mat6* J_j);

// Robust (Huber) cost of a chi-square value with threshold delta^2, as in g2o: chi2 when
// chi2 <= delta^2, else 2 delta sqrt(chi2) - delta^2; `weight` receives the IRLS weight.
inline double huber_cost(double chi2, double delta, double* weight) {
  const double delta2 = delta * delta;
  if (chi2 <= delta2) {
    if (weight != nullptr) *weight = 1.0;
    return chi2;
  }
  const double e = std::sqrt(chi2);
  if (weight != nullptr) *weight = delta / e;
  return 2.0 * delta * e - delta2;
}

}  // namespace sp::opt
