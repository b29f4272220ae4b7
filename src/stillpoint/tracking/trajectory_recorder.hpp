#pragma once
// Every frame's pose stored relative to its reference keyframe, as ORB-SLAM's CameraTrajectory:
// when local BA or a loop correction moves the keyframe, the frame moves with it.
#include <vector>

#include "stillpoint/geometry/lie.hpp"
#include "stillpoint/map/map.hpp"

namespace sp::track {

struct TrajectoryEntry {
  std::size_t frame_index = 0;
  double stamp = 0;
  map::KeyframeId reference = map::kNoKeyframe;
  geo::SE3 T_c_ref;
};

struct ResolvedPose {
  double stamp = 0;
  geo::SE3 T_wc;
  // The map of the keyframe the pose resolved through, as it is now: after a merge, the map merged into
  // (the pose is then in its frame); a map never merged has its own frame.
  map::MapId map_id = map::kFirstMap;
};

class TrajectoryRecorder {
 public:
  void record(const TrajectoryEntry& e) { entries_.push_back(e); }
  // Takes back the frames from `first_frame` on (index order); returns how many.
  std::size_t withdraw_from(std::size_t first_frame);
  [[nodiscard]] std::size_t size() const { return entries_.size(); }
  [[nodiscard]] const std::vector<TrajectoryEntry>& entries() const { return entries_; }
  // World poses of all recorded frames with the map as it is now (culled keyframes are followed
  // through their spanning-tree parents).
  [[nodiscard]] std::vector<ResolvedPose> resolve(map::MapView& view) const;

 private:
  std::vector<TrajectoryEntry> entries_;
};

}  // namespace sp::track
