#pragma once
// The pose-graph step of a loop correction, split so that the graph is solved off the map lock: the
// essential graph is copied under one view, solved on the copy, and the solution applied under a later
// view to a map that tracking and local mapping kept changing meanwhile. move_keyframes / move_points
// apply any solution computed on a copy (the global BA's too).
#include <set>
#include <unordered_map>
#include <utility>
#include <vector>

#include "stillpoint/map/map.hpp"
#include "stillpoint/optimize/pose_graph.hpp"

namespace sp::loop {

struct EssentialGraph {
  std::vector<opt::PoseGraphVertex> vertices;  // solved in place
  std::vector<opt::PoseGraphEdge> edges;
  std::unordered_map<map::KeyframeId, geo::SE3> start;  // each vertex's pose as copied
};

// Keyframe pose changes solved on a copy: id -> (pose as copied, solved pose).
using KeyframeMoves = std::unordered_map<map::KeyframeId, std::pair<geo::SE3, geo::SE3>>;

// Each keyframe in `moves` goes from -> to; one that moved to T meanwhile (local BA) takes T * from^-1 *
// to, keeping that motion on top. A live keyframe not in `moves` (made meanwhile) follows its
// spanning-tree parent's move and is added to `moves`.
void move_keyframes(map::MapView& view, KeyframeMoves& moves);

// Moves each live point with the move of the keyframe anchor_of(id, point) names (kNoKeyframe: stays).
template <class AnchorOf>
void move_points(map::MapView& view, const KeyframeMoves& moves, AnchorOf anchor_of) {
  for (const auto& [pid, p] : view.points()) {
    if (p.bad) continue;
    const auto it = moves.find(anchor_of(pid, p));
    if (it == moves.end()) continue;
    map::MapPoint* mp = view.point(pid);
    mp->position = it->second.second.inverse() * (it->second.first * mp->position);
  }
}

// Spanning tree, strong covisibility (weight >= 100) and loop edges between the keyframes in
// `old_pose` (their poses before the correction). Old edges keep the relative poses of `old_pose`; the
// new loop edge query-match and the links the fusion made (`loop_links`, as (min, max) pairs) are
// measured with the corrected poses. Fixed: the first keyframe, the match, and other maps' keyframes.
EssentialGraph essential_graph(const map::MapReader& view, map::KeyframeId query, map::KeyframeId match,
                               const std::unordered_map<map::KeyframeId, geo::SE3>& old_pose,
                               const std::set<std::pair<map::KeyframeId, map::KeyframeId>>& loop_links);

// Applies a solved graph with move_keyframes; points follow the keyframe that corrected them
// (`corrected_by`), else their reference keyframe, and get their normals and depth range again.
void apply_pose_graph(map::MapView& view, const EssentialGraph& solved,
                      const std::unordered_map<map::PointId, map::KeyframeId>& corrected_by,
                      const map::ScalePyramid& pyramid);

}  // namespace sp::loop
