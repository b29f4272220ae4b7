#pragma once
// The pose-graph step of a loop correction, split so that the graph is solved off the map lock: the
// essential graph is copied under one view, solved on the copy, and the solution applied under a later
// view to a map that tracking and local mapping kept changing meanwhile.
#include <set>
#include <unordered_map>
#include <utility>
#include <vector>

#include "stillpoint/map/map.hpp"
#include "stillpoint/optimize/pose_graph.hpp"

namespace sp::loop {

struct EssentialGraph {
  std::vector<opt::PoseGraphVertex> vertices;
  std::vector<opt::PoseGraphEdge> edges;
};

// Spanning tree, strong covisibility (weight >= 100) and loop edges between the keyframes in
// `old_pose` (their poses before the correction). Old edges keep the relative poses of `old_pose`; the
// new loop edge query-match and the links the fusion made (`loop_links`, as (min, max) pairs) are
// measured with the corrected poses. Fixed: the first keyframe, the match, and other maps' keyframes.
EssentialGraph essential_graph(const map::MapReader& view, map::KeyframeId query, map::KeyframeId match,
                               const std::unordered_map<map::KeyframeId, geo::SE3>& old_pose,
                               const std::set<std::pair<map::KeyframeId, map::KeyframeId>>& loop_links);

// Applies a solved graph: a keyframe solved from pose A to B becomes B, or T * A^-1 * B if it moved to
// T meanwhile (local BA keeps its motion on top); a keyframe made meanwhile follows its spanning-tree
// parent. Points follow the keyframe that corrected them (`corrected_by`), else their reference
// keyframe, and get their normals and depth range again.
void apply_pose_graph(map::MapView& view, const EssentialGraph& solved,
                      const std::unordered_map<map::KeyframeId, geo::SE3>& solved_from,
                      const std::unordered_map<map::PointId, map::KeyframeId>& corrected_by,
                      const map::ScalePyramid& pyramid);

}  // namespace sp::loop
