#include "stillpoint/tracking/trajectory_recorder.hpp"

#include <algorithm>

namespace sp::track {

std::size_t TrajectoryRecorder::withdraw_from(std::size_t first_frame) {
  const std::size_t before = entries_.size();
  std::erase_if(entries_, [first_frame](const TrajectoryEntry& e) { return e.frame_index >= first_frame; });
  return before - entries_.size();
}

std::vector<ResolvedPose> TrajectoryRecorder::resolve(map::MapView& view) const {
  std::vector<ResolvedPose> out;
  out.reserve(entries_.size());
  for (const auto& e : entries_) {
    geo::SE3 T_c_ref = e.T_c_ref;
    const map::Keyframe* ref = view.keyframe(e.reference);
    for (int hops = 0; ref != nullptr && ref->bad && hops < 1000; ++hops) {
      T_c_ref = T_c_ref * ref->T_c_parent;
      ref = view.keyframe(ref->parent);
    }
    if (ref == nullptr) continue;
    out.push_back({e.stamp, (T_c_ref * ref->T_cw).inverse(), ref->map_id});
  }
  return out;
}

}  // namespace sp::track
