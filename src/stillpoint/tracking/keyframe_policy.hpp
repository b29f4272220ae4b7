#pragma once
// When does the tracker hand a new keyframe to local mapping? Two policies behind one interface:
// ORB-SLAM3's RGB-D heuristics and the paper's adaptive-threshold selection (§III-A).
#include <Eigen/Core>
#include <limits>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "stillpoint/common/config_reader.hpp"

namespace sp::track {

// One tracked map point as the adaptive policy sees it.
struct ViewChange {
  float u = 0, v = 0;   // pixel in the current frame
  float angle_deg = 0;  // angle between the viewing rays from the reference keyframe and from now
};

struct KeyframeCandidate {
  std::size_t frames_since_keyframe = 0;
  double fps = 30;
  int tracked_inliers = 0;    // inlier matches after local-map tracking
  int reference_tracked = 0;  // points of the reference keyframe seen by enough keyframes
  int close_tracked = 0;      // tracked features with close depth
  int close_untracked = 0;    // close-depth features with no map point
  std::size_t keyframes_in_map = 0;
  bool mapping_idle = true;
  std::size_t mapping_queue = 0;
  int image_width = 640, image_height = 480;
  // How far the frame is from its reference keyframe (camera centre, rotation); unknown: infinite.
  double reference_translation_m = std::numeric_limits<double>::infinity();
  double reference_rotation_deg = std::numeric_limits<double>::infinity();
  std::vector<ViewChange> view_changes;  // filled only for policies that ask for it
};

struct KeyframePolicyConfig {
  std::string policy = "heuristic";   // heuristic | adaptive
  double max_interval_s = 1.0;        // s, a keyframe at least this often when mapping is idle
  double min_interval_s = 0.0;        // s, "mapping idle" alone never inserts sooner than this
  double reference_ratio = 0.75;      // inliers below this share of the reference's points -> new keyframe
  int min_inliers = 15;               // never insert from a frame tracked this weakly
  int close_tracked_min = 100;        // fewer tracked close points than this ...
  int close_untracked_min = 70;       // ... while this many close points are new -> new keyframe
  std::size_t max_mapping_queue = 3;  // keyframes waiting in local mapping before insertion pauses
  // Adaptive policy (paper §III-A).
  double effective_angle_deg = 30.0;  // a point is "effective" once its viewing angle changed this much
  // What the angle is measured against: "keyframe" = the ray from the reference keyframe's centre;
  // "point" = the point's mean viewing direction over every keyframe that saw it (docs/keyframe_policy.md).
  std::string effective_reference = "keyframe";
  double effective_share = 0.25;  // effective points needed, as a share of the tracked inliers
  int effective_min = 20;         // ... and never fewer than this
  // Both policies: no keyframe while the camera is still at its reference keyframe's place (within both
  // distances) tracking at least hold_min_tracked inliers: a new keyframe there sees nothing new, and
  // on a still camera each one re-anchors the sub-pixel alignment to a noisier pose
  // (docs/tracking_precision.md). 0: never held.
  int hold_min_tracked = 0;
  double hold_max_translation_m = 0.02;
  double hold_max_rotation_deg = 1.0;
  static KeyframePolicyConfig from_yaml(const ConfigReader& r);
};

// How often each rule of a policy fired, in the policy's own rule order: (stable JSON key, count).
using KeyframeRuleCounts = std::vector<std::pair<std::string, std::size_t>>;

class KeyframePolicy {
 public:
  virtual ~KeyframePolicy() = default;
  [[nodiscard]] virtual bool needs_view_changes() const { return false; }
  // Decides and counts the rule that decided (thread-safe counters; decide itself is called by one thread).
  [[nodiscard]] virtual bool decide(const KeyframeCandidate& c) const = 0;
  [[nodiscard]] virtual std::string name() const = 0;
  // Counts since construction (stats.json "keyframe_rules"); docs/keyframe_policy.md names each rule.
  [[nodiscard]] virtual KeyframeRuleCounts rule_counts() const = 0;
};

std::unique_ptr<KeyframePolicy> make_keyframe_policy(const KeyframePolicyConfig& config);

// The adaptive policy's distribution check on a 3x3 count matrix (exposed for tests).
struct GridBalance {
  double t1 = 0;  // distance of the count matrix's centre of gravity from the centre cell (Eqs. 2-4)
  double t2 = 0;  // spread of the two largest cells: (M2/M1) x distance between them / 2√2 (Eq. 5), [0, 1]
  [[nodiscard]] bool spread_out() const { return t2 > t1; }
};
GridBalance grid_balance(const Eigen::Matrix3i& counts);
// Angle (degrees) between a point's mean viewing direction `normal` (unit, keyframe -> point) and the
// ray from center_now to the point.
double angle_from_normal_deg(const Eigen::Vector3d& point, const Eigen::Vector3d& normal,
                             const Eigen::Vector3d& center_now);
// Angle (degrees) between the rays from two camera centres to a point: how much its view changed.
double viewing_angle_change_deg(const Eigen::Vector3d& point, const Eigen::Vector3d& center_ref,
                                const Eigen::Vector3d& center_now);
Eigen::Matrix3i effective_point_grid(const std::vector<ViewChange>& changes, int width, int height,
                                     double min_angle_deg);

}  // namespace sp::track
