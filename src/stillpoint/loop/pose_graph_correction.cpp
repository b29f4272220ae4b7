#include "stillpoint/loop/pose_graph_correction.hpp"

namespace sp::loop {

EssentialGraph essential_graph(const map::MapReader& view, map::KeyframeId query, map::KeyframeId match,
                               const std::unordered_map<map::KeyframeId, geo::SE3>& old_pose,
                               const std::set<std::pair<map::KeyframeId, map::KeyframeId>>& loop_links) {
  EssentialGraph g;
  const map::MapId loop_map = view.keyframe(match)->map_id;
  const std::vector<map::KeyframeId> ids = view.keyframe_ids_sorted();
  auto relative_old = [&](map::KeyframeId i, map::KeyframeId j) {
    return old_pose.at(i) * old_pose.at(j).inverse();
  };
  for (map::KeyframeId k : ids) {
    // A keyframe made after the correction began has no old geometry: it follows its parent.
    if (!old_pose.contains(k)) continue;
    const map::Keyframe* kf = view.keyframe(k);
    // Keyframes of other maps (not merged yet) share no edge with the loop's map: held as they are.
    g.vertices.push_back({k.value(), kf->T_cw, k == ids.front() || k == match || kf->map_id != loop_map});
    g.start.emplace(k, kf->T_cw);
    if (kf->parent != map::kNoKeyframe && old_pose.contains(kf->parent) && !view.keyframe(kf->parent)->bad) {
      g.edges.push_back({k.value(), kf->parent.value(), relative_old(k, kf->parent), 1.0});
    }
    for (const auto& [other, w] : kf->covisibility) {
      if (other < k && w >= 100 && other != kf->parent && old_pose.contains(other)) {
        g.edges.push_back({k.value(), other.value(),
                           loop_links.contains({other, k}) ? kf->T_cw * view.keyframe(other)->T_cw.inverse()
                                                           : relative_old(k, other),
                           1.0});
      }
    }
    for (map::KeyframeId other : kf->loop_edges) {
      if (other >= k || !old_pose.contains(other)) continue;
      const bool new_edge = (k == query && other == match) || (k == match && other == query);
      // The new loop edge is measured with the corrected pose; old loop edges keep their geometry.
      g.edges.push_back({k.value(), other.value(),
                         new_edge ? kf->T_cw * view.keyframe(other)->T_cw.inverse() : relative_old(k, other),
                         1.0});
    }
  }
  return g;
}

void move_keyframes(map::MapView& view, KeyframeMoves& moves) {
  for (const auto& [k, move] : moves) {
    map::Keyframe* kf = view.keyframe(k);
    if (kf == nullptr) continue;
    const auto& [from, to] = move;
    // Unmoved keyframes take the solution itself, bit for bit.
    kf->T_cw = kf->T_cw.matrix() == from.matrix() ? to : kf->T_cw * from.inverse() * to;
  }
  for (map::KeyframeId k : view.keyframe_ids_sorted()) {  // parents before children
    if (moves.contains(k)) continue;
    map::Keyframe* kf = view.keyframe(k);
    const auto parent = moves.find(kf->parent);
    if (parent == moves.end()) continue;
    const geo::SE3 from = kf->T_cw;
    kf->T_cw = kf->T_cw * parent->second.first.inverse() * parent->second.second;
    moves.emplace(k, std::pair{from, kf->T_cw});
  }
}

void apply_pose_graph(map::MapView& view, const EssentialGraph& solved,
                      const std::unordered_map<map::PointId, map::KeyframeId>& corrected_by,
                      const map::ScalePyramid& pyramid) {
  KeyframeMoves moves;
  for (const auto& v : solved.vertices) {
    const map::KeyframeId id{v.id};
    moves.emplace(id, std::pair{solved.start.at(id), v.T_cw});
  }
  move_keyframes(view, moves);
  move_points(view, moves, [&corrected_by](map::PointId pid, const map::MapPoint& p) {
    const auto by = corrected_by.find(pid);
    return by != corrected_by.end() ? by->second : p.reference;
  });
  for (const auto& [pid, p] : view.points()) {
    if (!p.bad) view.update_point_normal_and_depth(pid, pyramid);
  }
}

}  // namespace sp::loop
