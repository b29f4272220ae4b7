#pragma once
// Motion-only optimisation of one camera pose against fixed map points (ORB-SLAM's
// PoseOptimization): a hand-written Levenberg-Marquardt on the 6-dof left increment of T_cw
// (T_cw <- exp(delta) T_cw), robust Huber kernel, outliers re-classified by chi-square each round;
// optionally a weak Gaussian prior on the pose (the motion model's prediction).
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
  // Standard deviations of the motion prior (the constant-velocity prediction as a Gaussian prior on
  // the pose); 0 for both: no prior. Weak next to a few dozen well-spread points, it only decides
  // the directions the points leave unconstrained: a wall strip at one depth beside a person filling
  // the view cannot tell a sideways step from a turn (docs/tracking_precision.md). [0, 1] m, [0, 45] deg
  double motion_prior_m = 0.01;
  double motion_prior_deg = 1.0;
  // The prior only in solves with fewer matched map points than this (0: every solve): with many
  // points spread over the view it is not needed, and a wrong prediction would only pull.
  int motion_prior_max_matches = 100;
  // An observation whose chi-square at the start pose is above this many times the outlier threshold
  // sits out the first round, when the start pose fits at least half of them within the threshold
  // (0: off). A few close points on a person the detector missed, off by 20 px where the rest are
  // off by 1, otherwise drag the first round's pose centimetres sideways, and there they fit.
  double start_outlier_factor = 0.0;
  // ... only in solves with the motion prior (few matched points, where a few can decide the pose).
  bool start_outlier_with_prior_only = true;
  [[nodiscard]] bool has_motion_prior() const { return motion_prior_m > 0.0 && motion_prior_deg > 0.0; }
  static PoseOptimizerConfig from_yaml(const ConfigReader& r);
};

// A Gaussian prior on T_cw: residual log(T_cw * prior_T_cw^-1) = [rho; phi], weighted by 1/sigma.
struct PosePrior {
  geo::SE3 T_cw;
  double sigma_translation_m = 0.01;
  double sigma_rotation_rad = 0.01;
};

struct PoseOptimizationResult {
  int inliers = 0;            // observations that passed the last chi-square test
  std::vector<bool> outlier;  // per observation, from the last round (also true for z <= 0)
};

// Refines T_cw in place. Needs at least 3 observations, otherwise T_cw is left unchanged and every
// observation is reported as an outlier. Deterministic.
PoseOptimizationResult optimize_pose(geo::SE3& T_cw, const std::vector<PoseObservation>& observations,
                                     const CameraModel& camera, const PoseOptimizerConfig& config,
                                     const PosePrior* prior = nullptr);

}  // namespace sp::opt
