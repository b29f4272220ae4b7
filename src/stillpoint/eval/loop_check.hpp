#pragma once
// Judges a closed loop against ground truth: a loop is true when the relative pose it estimated
// between the two keyframes agrees with the ground-truth relative pose (RGB-D loops are metric, so a
// right loop is off by centimetres, a wrong place by metres or by a large angle).
#include <optional>
#include <vector>

#include "stillpoint/geometry/lie.hpp"
#include "stillpoint/io/trajectory_io.hpp"

namespace sp::eval {

struct LoopCheckThresholds {
  double max_translation_m = 0.10;      // relative-pose translation error of a true loop
  double max_rotation_deg = 5.0;        // relative-pose rotation error of a true loop
  double max_time_difference_s = 0.02;  // ground truth must exist this close to both stamps
};

struct LoopCheck {
  double translation_error_m = 0, rotation_error_deg = 0;
  double gt_distance_m = 0;  // how far apart the two keyframes really were
  bool is_true = false;
};

// T_query_match: camera query <- camera match, as estimated. nullopt when ground truth lacks a stamp.
std::optional<LoopCheck> check_loop(const std::vector<io::StampedPose>& gt, double query_stamp,
                                    double match_stamp, const geo::SE3& T_query_match,
                                    const LoopCheckThresholds& thresholds = {});

}  // namespace sp::eval
