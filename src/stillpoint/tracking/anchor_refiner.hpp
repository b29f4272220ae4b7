#pragma once
// Sub-pixel positions for tracked features, aligned with a fixed anchor image.
//
// ORB corners are re-detected in every frame on integer pixels of their pyramid level, and the
// detection moves by a pixel or more from frame to frame with image noise (scale^level pixels at
// level 0 for coarse levels). A still camera's pose then jitters by ~0.05 deg per frame where
// optical-flow trackers such as NGD-SLAM jitter by ~0.013 deg (docs/tracking_precision.md). Here
// every inlier feature matched to a point that the anchor keyframe (the last keyframe tracking made)
// observes is aligned by Lucas-Kanade with the anchor's patch around that observation: one fixed
// reference, so the positions are sub-pixel and do not drift. Only where a translation-only patch
// alignment is valid: small roll and scale change and a small view change since the anchor.
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "stillpoint/common/config_reader.hpp"
#include "stillpoint/geometry/camera.hpp"
#include "stillpoint/geometry/lie.hpp"
#include "stillpoint/map/map.hpp"
#include "stillpoint/tracking/frame.hpp"
#include "stillpoint/tracking/local_map_snapshot.hpp"

namespace sp::track {

struct AnchorRefinerConfig {
  bool enabled = true;
  int anchors = 1;                   // most recent tracking keyframes kept as anchors (newest tried first)
  int window = 11;                   // px, square Lucas-Kanade window at level 0
  int pyramid_levels = 0;            // Lucas-Kanade pyramid levels above level 0
  double max_shift = 1.5;            // pixels of the feature's own level, refined vs detected position
  double max_roll_deg = 4.0;         // rotation about the optical axis since the anchor
  double max_scale_change = 0.08;    // |depth at anchor / depth now - 1| per point
  double max_view_change_deg = 8.0;  // angle at the point between the anchor's and the current ray
  double max_error = 12.0;           // mean absolute grey difference of the aligned patch
  double max_round_trip = 0.0;       // px, aligned back onto the anchor it must land this close (0: no check)
  bool skip_suspect = true;          // features near detected objects or moving flow keep their detection
  bool level0_weight = true;         // refined features weighted as level 0 in pose optimisation
  double refined_weight = 1.0;       // ... times this (LK positions are more precise than detections)
  // Near an anchor (within both distances), with at least `aligned_only_min` aligned features, the pose
  // solve after the alignment uses the aligned features alone. Farther away the aligned set is smaller
  // and a translation-only warp can bias it, so every feature stays. 0 min: never.
  int aligned_only_min = 0;
  double aligned_only_max_translation_m = 0.02;
  double aligned_only_max_rotation_deg = 1.0;
  // What the unaligned features left out of that solve are: "kept" (the inlier/outlier status of the
  // solve before) or "tracked" (all inliers; the first version: a still camera then keeps one keyframe,
  // but a replayed start adds keyframes to the map it revisits; docs/tracking_precision.md).
  std::string aligned_only_unaligned = "kept";
  static AnchorRefinerConfig from_yaml(const ConfigReader& r);
};

struct AnchorRefinerStats {
  std::size_t frames = 0;               // frames with an anchor to refine against
  std::size_t candidates = 0;           // inlier features whose point the anchor observes, geometry valid
  std::size_t refined = 0;              // ... moved to their aligned position
  std::size_t aligned_only_solves = 0;  // pose solves that used the aligned features alone
};

class AnchorRefiner {
 public:
  AnchorRefiner(AnchorRefinerConfig config, geo::CameraIntrinsics camera, map::ScalePyramid pyramid);

  // The keyframe just made from `frame` becomes the anchor (its grey image and keypoints are kept).
  void set_anchor(map::KeyframeId id, const Frame& frame);
  void reset() { anchors_.clear(); }
  [[nodiscard]] std::size_t anchors() const { return anchors_.size(); }

  // The anchors' keyframe ids, oldest first: a snapshot given to refine() keeps the points'
  // observations in them and their poses (LocalMapSnapshot::reset, add_pose).
  [[nodiscard]] std::vector<map::KeyframeId> anchor_ids() const;

  // Moves the keypoints (and virtual right coordinates) of the frame's inlier features that the
  // anchor observes to their Lucas-Kanade aligned positions. Marks them in `refined` (per feature).
  // Returns how many moved. Reads the map only through the snapshot (no lock held).
  int refine(const LocalMapSnapshot& map, Frame& frame, std::vector<bool>& refined);

  // Whether the pose solve that follows refine() should use the aligned features alone: the camera
  // is near an anchor and `aligned` (features refine() moved) is at least aligned_only_min.
  [[nodiscard]] bool aligned_only(const LocalMapSnapshot& map, const geo::SE3& T_cw, int aligned) const;

  [[nodiscard]] const AnchorRefinerStats& stats() const { return stats_; }
  void count_aligned_only_solve() { ++stats_.aligned_only_solves; }
  [[nodiscard]] const AnchorRefinerConfig& config() const { return config_; }

 private:
  [[nodiscard]] cv::Point2f raw(const cv::Point2f& undistorted) const;

  AnchorRefinerConfig config_;
  geo::CameraIntrinsics camera_;
  map::ScalePyramid pyramid_;
  struct Anchor {
    map::KeyframeId id = map::kNoKeyframe;
    geo::SE3 T_cw;
    std::vector<cv::Mat> pyramid;
    std::vector<cv::Point2f> raw;  // per feature, distorted (image) position
  };
  std::vector<Anchor> anchors_;  // oldest first
  AnchorRefinerStats stats_;
};

}  // namespace sp::track
