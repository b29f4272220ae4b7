#pragma once
// Internals of bundle adjustment shared by the Ceres and the native solver, public so the tests can
// check them; callers use run_bundle_adjustment (bundle_adjustment.hpp).
#include <Eigen/Core>
#include <atomic>
#include <cstddef>
#include <vector>

#include "stillpoint/geometry/lie.hpp"
#include "stillpoint/optimize/bundle_adjustment.hpp"

namespace sp::opt::detail {

// Per observation: the index of its keyframe and of its point in the problem's vectors.
struct BAIndex {
  std::vector<std::size_t> kf, pt;
};

// Throws sp::Error for duplicate ids or an observation naming an unknown keyframe/point.
BAIndex index_observations(const BAProblem& problem);

// Number of non-fixed keyframes that have at least one observation.
int count_free_keyframes(const BAProblem& problem, const BAIndex& index);

// The native Levenberg-Marquardt solver, whatever the problem size (run_bundle_adjustment adds the
// fallback to Ceres above kNativeBAMaxFreeKeyframes); `index` is index_observations(problem).
BAResult run_native_bundle_adjustment(BAProblem& problem, const CameraModel& camera, const BAConfig& config,
                                      const std::atomic<bool>* abort, BAIndex index);

// The robust cost 1/2 sum rho(chi2) (Huber, as the first pass) over the observations not flagged in
// `outlier`, and its gradient as the native solver accumulates it: per keyframe w.r.t. the left
// increment of T_cw (T_cw <- exp(delta) T_cw, zero for fixed or unobserved keyframes), per point
// w.r.t. p_w.
struct BAGradient {
  double cost = 0;
  std::vector<geo::Vec6> pose;
  std::vector<Eigen::Vector3d> point;
};
BAGradient native_ba_gradient(const BAProblem& problem, const CameraModel& camera, const BAConfig& config,
                              const std::vector<bool>& outlier);

}  // namespace sp::opt::detail
