#pragma once
// RGB-D geometric verification of one loop candidate, off the map lock: what it reads from the map is
// copied first (LoopEvidence, under two short MapReaders, see gather_evidence), then descriptor matches ->
// 3-D/3-D RANSAC SE(3) -> projection matches with pose refinement -> drift limit -> the query's neighbours
// re-check the pose, all on the copy. Tracking and local mapping go on meanwhile; the caller re-checks under
// its next view that the two keyframes are still alive before it trusts the result (LoopCloser::verify).
#include <optional>
#include <vector>

#include "stillpoint/geometry/camera.hpp"
#include "stillpoint/loop/drift_limit.hpp"
#include "stillpoint/map/map.hpp"
#include "stillpoint/tracking/frame.hpp"
#include "stillpoint/tracking/local_map_snapshot.hpp"

namespace sp::loop {

struct LoopVerifierConfig {
  int min_descriptor_matches = 20;   // BoW-candidate keyframes sharing fewer matches are dropped
  double ransac_threshold_m = 0.05;  // 3-D/3-D RANSAC inlier distance
  int min_ransac_inliers = 20;
  int min_projection_inliers = 40;  // inliers after refinement with projection matches
  // The loop pose must also hold for the query's best covisible keyframes (moved with it): of the first
  // verify_neighbours (0: no check), at least half must reach neighbour_min_inliers. A place that only
  // looks alike from one view (a symmetric room, a repeated poster) fails from the next ones.
  int verify_neighbours = 4;
  int neighbour_min_inliers = 30;
  // A loop whose correction is larger than odometry can have drifted since the matched keyframe is a
  // look-alike place (drift_limit.hpp).
  DriftLimitConfig drift;
};

// Everything verification reads, copied under two short views (gather_evidence, add_loop_side).
// Features are deep copies.
struct LoopEvidence {
  struct View {
    map::KeyframeId id = map::kNoKeyframe;
    geo::SE3 T_cw;
    map::FeatureSet features;
  };
  View query;
  map::KeyframeId match = map::kNoKeyframe;
  geo::SE3 T_match_cw;
  double query_stamp = 0, match_stamp = 0;
  // The match keyframe's features with a live map point: their descriptors and the points' positions.
  cv::Mat match_descriptors;  // one row per point
  std::vector<Eigen::Vector3d> match_positions;
  // The loop side's points (match + its 10 best covisibles), as ids and copies.
  std::vector<map::KeyframeId> loop_side;
  std::vector<map::PointId> local_points;
  track::LocalMapSnapshot points;
  // Poses of the live keyframes from match to query (ids in between), in id order: the path travelled.
  std::vector<geo::SE3> path_poses;
  // The query's best covisible keyframes outside the loop side, for the neighbour check.
  std::vector<View> neighbours;
};

// Evidence is copied in two steps, each under one short view, because most candidates fail the first
// check: gather_evidence copies the two keyframes (what descriptor matching and RANSAC read), and only
// for a candidate that passed them add_loop_side copies the loop side's points, the path's poses and the
// query's neighbours. Both return false / nullopt when a keyframe is missing or culled; gather_evidence
// also when the two belong to different maps (not merged yet: map merging's job, not a loop). The
// points' index is built after the caller's view ends: call finish_evidence() then.
std::optional<LoopEvidence> gather_evidence(const map::MapReader& view, map::KeyframeId query,
                                            map::KeyframeId match);
bool add_loop_side(const map::MapReader& view, LoopEvidence& evidence, int verify_neighbours);
void finish_evidence(LoopEvidence& evidence);

enum class LoopRejection {
  kNone,
  kFewDescriptorMatches,
  kRansacFailed,
  kFewProjectionInliers,
  kDrift,
  kNeighbours,
  kCulled,  // local mapping culled the query or the match between two copies
};

struct LoopVerification {
  LoopRejection rejection = LoopRejection::kNone;
  geo::SE3 T_query_w;  // the verified pose of the query keyframe
  int inliers = 0;     // projection inliers of the query at that pose
  // The points the projections found in view, whose visible counters the map should raise.
  track::PointCounterUpdates counters;
  [[nodiscard]] bool accepted() const { return rejection == LoopRejection::kNone; }
};

class LoopVerifier {
 public:
  LoopVerifier(LoopVerifierConfig config, geo::CameraIntrinsics camera, track::DepthModel depth,
               map::ScalePyramid pyramid);
  // Both read only the evidence and run without the map lock. match_and_align: descriptor matches and
  // 3-D/3-D RANSAC on gather_evidence's copy (rejection kFewDescriptorMatches or kRansacFailed, else
  // T_query_w is RANSAC's pose). refine: projection matches, refinement, drift limit and the neighbour
  // check on add_loop_side's copy, from that pose.
  [[nodiscard]] LoopVerification match_and_align(const LoopEvidence& evidence) const;
  void refine(const LoopEvidence& evidence, LoopVerification& result) const;
  // Both steps on evidence that already holds the loop side.
  [[nodiscard]] LoopVerification verify(const LoopEvidence& evidence) const;

 private:
  // Projects the loop side's points into a view at T_cw and refines T_cw on the matches; the inliers.
  int project_and_refine(const LoopEvidence& evidence, const LoopEvidence::View& kf, geo::SE3& T_cw,
                         track::PointCounterUpdates& counters) const;

  LoopVerifierConfig config_;
  geo::CameraIntrinsics camera_;
  track::DepthModel depth_;
  map::ScalePyramid pyramid_;
};

}  // namespace sp::loop
