#include "stillpoint/optimize/ba_conditioning.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <limits>

#include "stillpoint/optimize/bundle_adjustment_native.hpp"

namespace sp::opt {

std::vector<double> keyframe_centre_std(const BAProblem& problem, const CameraModel& camera) {
  // The same indexing (and the same errors for unknown or duplicate ids) as the BA itself.
  const detail::BAIndex index = detail::index_observations(problem);
  std::vector<std::vector<std::size_t>> observations_of(problem.points.size());
  for (std::size_t i = 0; i < problem.observations.size(); ++i) observations_of[index.pt[i]].push_back(i);

  std::vector<geo::Mat6> information(problem.keyframes.size(), geo::Mat6::Zero());
  struct Row {
    std::size_t keyframe;
    Eigen::Matrix<double, 3, 6> J_pose;
    Eigen::Matrix3d J_point;
  };
  std::vector<Row> rows;
  for (std::size_t p = 0; p < problem.points.size(); ++p) {
    if (observations_of[p].size() < 2) continue;  // seen once: the point absorbs it, the pose learns nothing
    rows.clear();
    Eigen::Matrix3d H_point = Eigen::Matrix3d::Zero();
    for (std::size_t i : observations_of[p]) {
      const BAObservation& o = problem.observations[i];
      const std::size_t k = index.kf[i];
      const geo::SE3& T = problem.keyframes[k].T_cw;
      const Reprojection r =
          evaluate_reprojection(camera, T.rotation(), T.translation(), problem.points[p].p_w, o.uv, o.u_right,
                                std::sqrt(std::max(o.inv_sigma2, 0.0)), true, true);
      if (r.depth <= 0) continue;
      H_point += r.J_point.transpose() * r.J_point;
      rows.push_back({k, r.J_pose, r.J_point});
    }
    if (rows.size() < 2) continue;
    const Eigen::LDLT<Eigen::Matrix3d> point_solver(H_point);
    if (point_solver.info() != Eigen::Success || point_solver.vectorD().minCoeff() <= 1e-12) continue;
    for (const Row& row : rows) {
      if (problem.keyframes[row.keyframe].fixed) continue;
      // Schur complement of the point, other keyframes held fixed:
      // J_T' J_T - (J_T' J_X) H_XX^-1 (J_X' J_T).
      const Eigen::Matrix<double, 6, 3> coupling = row.J_pose.transpose() * row.J_point;
      information[row.keyframe] +=
          row.J_pose.transpose() * row.J_pose - coupling * point_solver.solve(coupling.transpose());
    }
  }

  std::vector<double> centre_std(problem.keyframes.size(), 0.0);
  for (std::size_t k = 0; k < problem.keyframes.size(); ++k) {
    if (problem.keyframes[k].fixed) continue;
    const Eigen::FullPivLU<geo::Mat6> lu(information[k]);
    if (!lu.isInvertible()) {
      centre_std[k] = std::numeric_limits<double>::infinity();
      continue;
    }
    // Left increments exp([rho; phi]) * T_cw move the centre by -R' rho (first order): the centre's
    // covariance is the rho block rotated, with the same eigenvalues.
    const geo::Mat6 covariance = lu.inverse();
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(covariance.topLeftCorner<3, 3>());
    centre_std[k] = std::sqrt(std::max(eigen.eigenvalues().maxCoeff(), 0.0));
  }
  return centre_std;
}

}  // namespace sp::opt
