#pragma once
// A frame being tracked: its features (dynamic ones already removed), matches to map points and pose.
#include <opencv2/core.hpp>
#include <vector>

#include "stillpoint/geometry/camera.hpp"
#include "stillpoint/geometry/lie.hpp"
#include "stillpoint/map/feature_set.hpp"
#include "stillpoint/map/types.hpp"

namespace sp::track {

struct DepthModel {
  double depth_min = 0.1;    // m, readings below are invalid
  double depth_max = 8.0;    // m, readings above are invalid
  double bf = 40.0;          // virtual baseline x fx (m*px), as ORB-SLAM's Camera.bf for RGB-D
  double close_depth = 3.2;  // m, "close" points are reliable enough to create map points from one view
};

struct Frame {
  std::size_t index = 0;
  double stamp = 0;
  map::FeatureSet features;
  feat::FeatureGrid grid;
  std::vector<map::PointId> points;  // per feature
  std::vector<bool> outlier;         // per feature, set by pose optimisation
  // Per feature: kept by dynamic culling but in or near a detected object or a moving flow point
  // (empty = none). The pose guard re-solves without them when the pose jumps.
  std::vector<bool> suspect;
  // Features culled only because they lie on people proven still (empty unless
  // dynamic.motion.reserve_still_people): kept with a keyframe made from this frame; the tracker adds
  // them (and maps recent keyframes' reserves) only when the frame cannot be tracked without them.
  map::FeatureSet reserve;
  geo::SE3 T_cw;
  bool has_pose = false;
  map::KeyframeId reference = map::kNoKeyframe;
  cv::Mat gray;               // kept for the next frame's optical flow
  cv::Mat thumbnail;          // small colour image
  std::size_t extracted = 0;  // features before dynamic culling
  std::size_t culled = 0;     // features removed as dynamic

  [[nodiscard]] Eigen::Vector3d camera_center() const { return T_cw.inverse().translation(); }
  void reset_matches() {
    points.assign(features.size(), map::kNoPoint);
    outlier.assign(features.size(), false);
  }
  [[nodiscard]] int matched() const;
};

// Fills depth and the virtual stereo coordinate from a registered depth image (metres).
// `keypoints_distorted` are the raw detections (depth is looked up there); `features.keypoints`
// already hold the undistorted positions.
void attach_depth(map::FeatureSet& features, const std::vector<cv::KeyPoint>& keypoints_distorted,
                  const cv::Mat& depth, const DepthModel& model);

// Undistorts keypoint positions in place (identity without distortion).
std::vector<cv::KeyPoint> undistort_keypoints(const std::vector<cv::KeyPoint>& keypoints,
                                              const geo::CameraIntrinsics& camera);

}  // namespace sp::track
