#pragma once
// Motion-only optimisation of one camera pose against fixed map points (ORB-SLAM's
// PoseOptimization): a hand-written Levenberg-Marquardt on the 6-dof left increment of T_cw
// (T_cw <- exp(delta) T_cw), robust Huber kernel, outliers re-classified by chi-square each round.
#include <Eigen/Core>
#include <vector>

#include "stillpoint/common/config_reader.hpp"
#include "stillpoint/geometry/lie.hpp"
#include "stillpoint/optimize/residuals.hpp"

namespace sp::opt {

struct PoseObservation {
  Eigen::Vector3d point_w = Eigen::Vector3d::Zero();
  Eigen::Vector2d uv = Eigen::Vector2d::Zero();  // undistorted keypoint, pixels
  double u_right = -1;                           // virtual right u, pixels; < 0 => monocular
  double inv_sigma2 = 1;                         // 1 / sigma^2 of the keypoint's pyramid level, 1/px^2
};

struct PoseOptimizerConfig {
  int rounds = 4;              // outlier re-classification rounds, [1, 20]
  int iterations = 10;         // LM iterations per round, [1, 100]
  double chi2_mono = 5.991;    // chi-square threshold, 2 dof (95 %), [0.1, 1000]
  double chi2_stereo = 7.815;  // chi-square threshold, 3 dof (95 %), [0.1, 1000]
  // A round stops once an accepted step lowers the cost by less than this share of it, [0, 0.1]:
  // 1e-5 against 1e-8 cut tracking's pose time ~10 % with the same ATE (docs/tracking_precision.md)
  double min_relative_decrease = 1e-5;
  static PoseOptimizerConfig from_yaml(const ConfigReader& r);
};

struct PoseOptimizationResult {
  int inliers = 0;            // observations that passed the last chi-square test
  std::vector<bool> outlier;  // per observation, from the last round (also true for z <= 0)
};

// Refines T_cw in place. Needs at least 3 observations, otherwise T_cw is left unchanged and every
// observation is reported as an outlier. Deterministic.
PoseOptimizationResult optimize_pose(geo::SE3& T_cw, const std::vector<PoseObservation>& observations,
                                     const CameraModel& camera, const PoseOptimizerConfig& config);

}  // namespace sp::opt
