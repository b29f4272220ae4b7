#pragma once
// Map records. They are plain data owned by the Map and reachable only through a MapView,
// which holds the map's lock: the lock discipline lives in one place (map.hpp).
#include <Eigen/Core>
#include <algorithm>
#include <map>
#include <opencv2/core.hpp>
#include <set>
#include <vector>

#include "stillpoint/geometry/lie.hpp"
#include "stillpoint/map/feature_set.hpp"
#include "stillpoint/map/observation_list.hpp"
#include "stillpoint/map/types.hpp"

namespace sp::map {

struct Keyframe {
  KeyframeId id = kNoKeyframe;
  // Keyframes of different maps share no points, so covisibility never links them; what picks
  // keyframes by id or recency (relocalisation, loop candidates, gauge roots) checks it.
  MapId map_id = kFirstMap;
  std::size_t frame_index = 0;
  double stamp = 0;
  geo::SE3 T_cw;
  FeatureSet features;
  feat::FeatureGrid index;
  std::vector<PointId> points;  // per feature, kNoPoint when unmatched
  cv::Mat thumbnail;            // small colour image for place recognition and reports

  std::map<KeyframeId, int> covisibility;  // keyframe -> number of shared points (>= threshold)
  KeyframeId parent = kNoKeyframe;         // spanning tree
  std::set<KeyframeId> children;
  std::set<KeyframeId> loop_edges;
  bool bad = false;
  // > 0 while a stage keeps using this keyframe across views (a loop between verification and
  // correction); MapView::erase_keyframe refuses it then. Taken and released through MapView.
  int culling_holds = 0;
  geo::SE3 T_c_parent;  // set when the keyframe is culled, so frames that referenced it still resolve
  // Culled keyframes stay as slim records (pose, parent) for the trajectory; their features,
  // thumbnail and point slots are released by MapView::purge_bad once retired long enough.
  KeyframeId retired_at = kNoKeyframe;  // next keyframe id when it was culled

  [[nodiscard]] Eigen::Vector3d camera_center() const { return T_cw.inverse().translation(); }
};

// Pyramid level at which a point with scale-invariance distance `max_distance` is expected to be
// detected from `distance` away.
int predict_level(double max_distance, double distance, const ScalePyramid& pyramid);

struct MapPoint {
  PointId id = kNoPoint;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  cv::Mat descriptor;  // 1 x 32 representative descriptor (min median distance)
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // mean viewing direction
  double min_distance = 0, max_distance = 0;          // scale-invariance distances
  ObservationList observations;                       // keyframe -> feature index, by keyframe id
  KeyframeId reference = kNoKeyframe;
  KeyframeId first_keyframe = kNoKeyframe;
  int visible = 1;  // times it projected into a tracked frame
  int found = 1;    // times it was matched there
  bool bad = false;
  PointId replaced_by = kNoPoint;
  KeyframeId retired_at = kNoKeyframe;  // next keyframe id when it went bad (purge_bad drops it later)

  [[nodiscard]] double found_ratio() const { return static_cast<double>(found) / std::max(1, visible); }
  // Pyramid level at which a point at `distance` is expected to be detected.
  [[nodiscard]] int predict_level(double distance, const ScalePyramid& pyramid) const;
};

}  // namespace sp::map
