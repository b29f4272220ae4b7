#pragma once
// Bundle adjustment of keyframe poses (T_cw) and map points with Ceres (ORB-SLAM's LocalBundleAdjustment;
// also usable as global BA with the first keyframe fixed). Two passes: Huber-robust first pass,
// chi-square outlier rejection (and points behind the camera), then a second pass without them.
// Point blocks are eliminated first (Schur complement). Deterministic with threads = 1.
//
// Two solvers behind the same function (BAConfig::solver): "native" (default), a hand-written
// Levenberg-Marquardt that follows Ceres' trust-region LM step for step (same damping, step
// acceptance and stopping rules) with an explicit Schur complement over fixed-size Eigen blocks and
// a dense reduced camera system; "ceres", Ceres with DENSE_SCHUR / SPARSE_SCHUR, the reference.
// The native solver hands problems with more than kNativeBAMaxFreeKeyframes free keyframes to Ceres
// (its reduced camera system is dense, 6n x 6n).
#include <Eigen/Core>
#include <atomic>
#include <cstdint>
#include <string>
#include <vector>

#include "stillpoint/common/config_reader.hpp"
#include "stillpoint/geometry/lie.hpp"
#include "stillpoint/optimize/residuals.hpp"

namespace sp::opt {

struct BAKeyframe {
  std::uint64_t id = 0;
  geo::SE3 T_cw;
  bool fixed = false;  // held constant (e.g. keyframes that see local points but are outside the window)
};

struct BAPoint {
  std::uint64_t id = 0;
  Eigen::Vector3d p_w = Eigen::Vector3d::Zero();
};

struct BAObservation {
  std::uint64_t keyframe_id = 0, point_id = 0;
  Eigen::Vector2d uv = Eigen::Vector2d::Zero();  // undistorted keypoint, pixels
  double u_right = -1;                           // virtual right u, pixels; < 0 => monocular
  double inv_sigma2 = 1;                         // 1 / sigma^2 of the keypoint's pyramid level
};

struct BAProblem {
  std::vector<BAKeyframe> keyframes;
  std::vector<BAPoint> points;
  std::vector<BAObservation> observations;
};

struct BAConfig {
  int iterations_first = 5;       // LM iterations of the robust first pass, [1, 1000]
  int iterations_second = 10;     // LM iterations after outlier removal, [0, 1000] (0 = single pass)
  double chi2_mono = 5.991;       // chi-square threshold, 2 dof, [0.1, 1000]
  double chi2_stereo = 7.815;     // chi-square threshold, 3 dof, [0.1, 1000]
  int threads = 1;                // Ceres threads, [1, 64]; 1 is deterministic
  std::string solver = "native";  // native | ceres (native falls back to Ceres above 60 free keyframes)
  // Ceres path: up to this many free keyframes the reduced camera system is factorised densely
  // (DENSE_SCHUR), above it sparsely (SPARSE_SCHUR), [0, 100000]. Global BA of a 900-frame loop
  // sequence, 263 free keyframes / 116k residuals: linear solver 1.9 s dense, 4.8 s SuiteSparse,
  // 7.7 s Eigen sparse (same iterations and result; docs/map_lock.md).
  int dense_schur_max_keyframes = 300;
  // SPARSE_SCHUR's library: "suite_sparse" (CHOLMOD, the fastest sparse one above) | "eigen".
  std::string sparse_library = "suite_sparse";
  static BAConfig from_yaml(const ConfigReader& r);
};

// Above this many free (non-fixed, observed) keyframes the native solver runs the Ceres path.
inline constexpr int kNativeBAMaxFreeKeyframes = 60;

struct BAResult {
  std::vector<bool> outlier;  // per observation: chi2 above threshold or behind the camera at the end
  bool aborted = false;       // the abort flag stopped the solve (state is the last accepted iterate)
  double initial_cost = 0;    // Ceres cost (1/2 sum of robustified chi2) before the first pass
  double final_cost = 0;      // Ceres cost after the last pass run (over that pass' observations)
  int iterations = 0;         // LM iterations over both passes
};

// Updates problem.keyframes[].T_cw (non-fixed) and problem.points[].p_w in place. Throws sp::Error
// for duplicate ids or an observation naming an unknown keyframe/point. Keyframes and points with no
// observation are left untouched. The caller fixes the gauge (at least one fixed keyframe for
// global BA). `abort` may be set from another thread; it is polled after every LM iteration.
BAResult run_bundle_adjustment(BAProblem& problem, const CameraModel& camera, const BAConfig& config,
                               const std::atomic<bool>* abort = nullptr);

}  // namespace sp::opt
