#pragma once
// Data association between a frame and map points: by projection (motion model, local map) and by
// descriptor (reference keyframe, relocalisation). ORB-SLAM's thresholds, written for RGB-D.
#include <vector>

#include "stillpoint/geometry/camera.hpp"
#include "stillpoint/map/map.hpp"
#include "stillpoint/tracking/frame.hpp"
#include "stillpoint/tracking/local_map_snapshot.hpp"

namespace sp::track {

struct MatchContext {
  const geo::CameraIntrinsics& camera;
  const map::ScalePyramid& pyramid;
  double bf;  // virtual baseline x fx, for the depth consistency check
};

inline constexpr int kDescriptorThHigh = 100;
inline constexpr int kDescriptorThLow = 50;

// Projects the map points matched in `last` into `cur` (whose T_cw is the prediction) and matches
// them within `radius` px (scaled by the pyramid level). Returns the number of new matches.
int match_last_frame(const LocalMapSnapshot& map, Frame& cur, const Frame& last, double radius,
                     const MatchContext& ctx);

// Matches local map points not matched yet; `radius_factor` multiplies the level scale (ORB-SLAM: 3
// for RGB-D). Points that project into the image count as "visible": `counters` collects them.
int match_local_points(const LocalMapSnapshot& map, Frame& cur, const std::vector<map::PointId>& local_points,
                       double radius_factor, const MatchContext& ctx, PointCounterUpdates& counters);
// The same under a view the caller holds (loop closing): the visible counters are raised at once.
int match_local_points(map::MapView& view, Frame& cur, const std::vector<map::PointId>& local_points,
                       double radius_factor, const MatchContext& ctx);

// Matches the frame's descriptors against the keyframe's map points (brute force, ratio test,
// orientation consistency). Used when the motion model fails and for relocalisation.
int match_keyframe(const LocalMapSnapshot::Keyframe& kf, Frame& cur, float ratio);

// Projects map points into a keyframe and merges each with the feature it lands on: the feature
// gains the observation, or, when it already has a point, the better-observed point replaces the
// other. Used by local mapping (neighbours) and loop closing (the two sides of a loop).
int fuse_into_keyframe(map::MapView& view, map::KeyframeId target, const std::vector<map::PointId>& points,
                       double radius, const MatchContext& ctx);

// Projects p_w with T_cw; returns false when behind the camera or outside the image.
bool project_point(const geo::SE3& T_cw, const Eigen::Vector3d& p_w, const geo::CameraIntrinsics& camera,
                   Eigen::Vector2d& uv, double& depth);

}  // namespace sp::track
