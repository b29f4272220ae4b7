#pragma once
// Local mapping: integrates each new keyframe into the map (point upkeep, culling of weak points,
// fusion of duplicates with neighbours), refines the neighbourhood with local bundle adjustment and
// culls redundant keyframes. One job per call; the stage that runs it owns the thread.
#include <atomic>
#include <vector>

#include "stillpoint/common/config_reader.hpp"
#include "stillpoint/geometry/camera.hpp"
#include "stillpoint/map/map.hpp"
#include "stillpoint/mapping/point_triangulator.hpp"
#include "stillpoint/optimize/bundle_adjustment.hpp"
#include "stillpoint/tracking/frame.hpp"

namespace sp::mapping {

struct LocalMappingConfig {
  std::size_t fusion_neighbours = 10;  // best covisibles searched for duplicates (ORB-SLAM RGB-D)
  double fusion_radius = 3.0;          // px at level 0
  bool local_ba = true;
  std::size_t ba_max_keyframes = 20;  // optimised keyframes (the rest that see the points stay fixed)
  // A local BA that moves a keyframe's centre further than this is dropped (poses, points and outlier
  // marks stay as they were): an ill-posed window, e.g. a person filling most of the view, can carry
  // the newest keyframe centimetres from where tracking put it (docs/tracking_precision.md) [0, 10];
  // 0 = off.
  double ba_max_keyframe_move_m = 0.0;
  // A free keyframe whose camera centre the window pins down worse than this (standard deviation from
  // the points it shares, 1 px level-0 noise; opt::keyframe_centre_std) keeps its tracked pose: it is
  // held fixed in that BA, the points and the other keyframes are still refined. Acts on the cause the
  // move bound above sees afterwards (docs/tracking_precision.md) [0, 10]; 0 = off.
  double ba_weak_keyframe_std_m = 0.0;
  double redundancy = 0.9;  // share of a keyframe's points seen by 3 others -> culled
  bool cull_keyframes = true;
  double min_found_ratio = 0.25;  // new points matched less often than this are dropped
  // New points with fewer weighted observations (a view with depth counts 2) two keyframes after
  // their birth are dropped; ORB-SLAM RGB-D drops those with <= 3, i.e. asks for 4.
  int min_weighted_observations = 3;
  // Culled points and keyframes are freed this many keyframes after they went bad (ids other stages
  // hold across views resolve until then); keeps memory flat on long runs.
  std::size_t purge_after_keyframes = 20;
  opt::BAConfig ba;
  TriangulationConfig triangulation;
  static LocalMappingConfig from_yaml(const ConfigReader& r);
};

struct LocalMappingStats {
  double ba_ms = 0;
  int culled_points = 0;
  int fused_points = 0;
  int triangulated_points = 0;
  double triangulation_ms = 0;
  int culled_keyframes = 0;
  std::size_t purged_records = 0;
  bool ba_aborted = false;
  bool ba_dropped = false;    // the BA moved a keyframe more than ba_max_keyframe_move_m: not applied
  int ba_held_keyframes = 0;  // free keyframes held fixed as weakly constrained (ba_weak_keyframe_std_m)
  bool ba_solved = false;     // a BA ran to the end (applied or dropped)
  double ba_largest_keyframe_move_m = 0;  // how far the solved BA carried its most-moved keyframe centre
};

class LocalMapper {
 public:
  LocalMapper(map::Map& map, LocalMappingConfig config, geo::CameraIntrinsics camera, track::DepthModel depth,
              map::ScalePyramid pyramid);

  // Integrates one keyframe (already in the map). `abort` lets a newer keyframe or a loop cut BA short.
  LocalMappingStats process(map::KeyframeId keyframe, const std::atomic<bool>* abort = nullptr);

 private:
  void integrate(map::MapView& view, map::KeyframeId kid);
  int cull_recent_points(map::MapView& view, map::KeyframeId kid);
  // New points from features no keyframe had mapped, matched with the best covisibles (lock-free
  // matching on copies; the map is locked only to copy and to write back).
  int create_new_points(map::KeyframeId kid);
  int fuse_neighbours(map::MapView& view, map::KeyframeId kid);
  bool local_bundle_adjustment(map::KeyframeId kid, const std::atomic<bool>* abort, LocalMappingStats& stats);
  int cull_keyframes(map::MapView& view, map::KeyframeId kid);

  map::Map& map_;
  LocalMappingConfig config_;
  geo::CameraIntrinsics camera_;
  track::DepthModel depth_;
  map::ScalePyramid pyramid_;
  opt::CameraModel camera_model_;
  PointTriangulator triangulator_;
  std::vector<map::PointId> recent_points_;
};

}  // namespace sp::mapping
