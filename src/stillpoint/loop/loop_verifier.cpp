#include "stillpoint/loop/loop_verifier.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <unordered_set>

#include "stillpoint/features/matching.hpp"
#include "stillpoint/geometry/ransac_se3.hpp"
#include "stillpoint/optimize/pose_optimizer.hpp"
#include "stillpoint/tracking/projection_matcher.hpp"

namespace sp::loop {

namespace {

map::FeatureSet deep_copy(const map::FeatureSet& f) {
  map::FeatureSet c = f;
  c.descriptors = f.descriptors.clone();  // a Mat copy shares its pixels; the copy must own them
  return c;
}

// The loop side: the match keyframe and its 10 best covisibles (ORB-SLAM's loop keyframe group).
constexpr std::size_t kLoopSideCovisibles = 10;

}  // namespace

std::optional<LoopEvidence> gather_evidence(const map::MapReader& view, map::KeyframeId query,
                                            map::KeyframeId match) {
  const map::Keyframe* q = view.keyframe(query);
  const map::Keyframe* m = view.keyframe(match);
  if (q == nullptr || m == nullptr || q->bad || m->bad) return std::nullopt;
  if (q->map_id != m->map_id) {
    spdlog::debug("loop candidate {}->{}: keyframes of different maps, left to map merging", query, match);
    return std::nullopt;
  }
  LoopEvidence e;
  e.query = {query, q->T_cw, deep_copy(q->features)};
  e.match = match;
  e.T_match_cw = m->T_cw;
  e.query_stamp = q->stamp;
  e.match_stamp = m->stamp;

  std::vector<int> rows;
  for (std::size_t i = 0; i < m->points.size(); ++i) {
    const map::MapPoint* p = m->points[i] == map::kNoPoint ? nullptr : view.live_point(m->points[i]);
    if (p == nullptr) continue;
    rows.push_back(static_cast<int>(i));
    e.match_positions.push_back(p->position);
  }
  e.match_descriptors.create(static_cast<int>(rows.size()), m->features.descriptors.cols, CV_8U);
  for (std::size_t r = 0; r < rows.size(); ++r)
    m->features.descriptors.row(rows[r]).copyTo(e.match_descriptors.row(static_cast<int>(r)));
  return e;
}

bool add_loop_side(const map::MapReader& view, LoopEvidence& e, int verify_neighbours) {
  const map::KeyframeId query = e.query.id, match = e.match;
  const map::Keyframe* q = view.keyframe(query);
  const map::Keyframe* m = view.keyframe(match);
  if (q == nullptr || m == nullptr || q->bad || m->bad) return false;
  e.loop_side = view.best_covisibles(match, kLoopSideCovisibles);
  e.loop_side.push_back(match);
  std::unordered_set<map::PointId> seen;
  for (map::KeyframeId k : e.loop_side) {
    const map::Keyframe* kf = view.keyframe(k);
    if (kf == nullptr || kf->bad) continue;
    for (map::PointId pid : kf->points) {
      if (pid != map::kNoPoint && seen.insert(pid).second) e.local_points.push_back(pid);
    }
  }
  e.points.reset({});
  e.points.copy_points(view, e.local_points);

  for (map::KeyframeId k : view.keyframe_ids_sorted()) {
    if (k < match || k > query) continue;
    const map::Keyframe* kf = view.keyframe(k);
    if (kf != nullptr && !kf->bad) e.path_poses.push_back(kf->T_cw);
  }

  if (verify_neighbours > 0) {
    for (map::KeyframeId n : view.best_covisibles(query, static_cast<std::size_t>(verify_neighbours))) {
      const map::Keyframe* nkf = view.keyframe(n);
      if (nkf == nullptr || nkf->bad ||
          std::find(e.loop_side.begin(), e.loop_side.end(), n) != e.loop_side.end())
        continue;
      e.neighbours.push_back({n, nkf->T_cw, deep_copy(nkf->features)});
    }
  }
  return true;
}

void finish_evidence(LoopEvidence& evidence) { evidence.points.index_copies(); }

LoopVerifier::LoopVerifier(LoopVerifierConfig config, geo::CameraIntrinsics camera, track::DepthModel depth,
                           map::ScalePyramid pyramid)
    : config_(config), camera_(camera), depth_(depth), pyramid_(std::move(pyramid)) {}

LoopVerification LoopVerifier::verify(const LoopEvidence& evidence) const {
  LoopVerification result = match_and_align(evidence);
  if (result.accepted()) refine(evidence, result);
  return result;
}

LoopVerification LoopVerifier::match_and_align(const LoopEvidence& e) const {
  LoopVerification out;
  const map::KeyframeId query = e.query.id, match = e.match;
  const map::FeatureSet& qf = e.query.features;

  // 1. Descriptor matches: query features with depth against the match keyframe's map points.
  std::vector<int> q_rows;
  for (std::size_t i = 0; i < qf.size(); ++i) {
    if (qf.depth[i] > 0) q_rows.push_back(static_cast<int>(i));
  }
  if (q_rows.size() < 20 || e.match_positions.size() < 20) {
    out.rejection = LoopRejection::kFewDescriptorMatches;
    return out;
  }
  cv::Mat q_desc(static_cast<int>(q_rows.size()), qf.descriptors.cols, CV_8U);
  for (std::size_t r = 0; r < q_rows.size(); ++r)
    qf.descriptors.row(q_rows[r]).copyTo(q_desc.row(static_cast<int>(r)));
  const auto matches = feat::match_ratio(q_desc, e.match_descriptors, 0.75f, track::kDescriptorThLow, true);
  if (static_cast<int>(matches.size()) < config_.min_descriptor_matches) {
    spdlog::debug("loop candidate {}->{}: {} descriptor matches, rejected", query, match, matches.size());
    out.rejection = LoopRejection::kFewDescriptorMatches;
    return out;
  }

  // 2. 3-D/3-D RANSAC: the match side's map points (world) against the query's depth points (camera).
  std::vector<Eigen::Vector3d> src, dst;
  for (const auto& mt : matches) {
    const auto qi = static_cast<std::size_t>(q_rows[static_cast<std::size_t>(mt.query)]);
    const auto& kp = qf.keypoints[qi];
    dst.push_back(camera_.unproject({kp.pt.x, kp.pt.y}, qf.depth[qi]));
    src.push_back(e.match_positions[static_cast<std::size_t>(mt.train)]);
  }
  geo::RansacSe3Config rc;
  rc.inlier_threshold = config_.ransac_threshold_m;
  rc.min_inliers = config_.min_ransac_inliers;
  rc.seed = static_cast<std::uint32_t>(query.value());
  const auto ransac = geo::estimate_se3_ransac(src, dst, rc);
  if (!ransac) {
    spdlog::debug("loop candidate {}->{}: RANSAC failed on {} matches", query, match, matches.size());
    out.rejection = LoopRejection::kRansacFailed;
    return out;
  }
  out.T_query_w = ransac->T_dst_src;
  return out;
}

void LoopVerifier::refine(const LoopEvidence& e, LoopVerification& out) const {
  const map::KeyframeId query = e.query.id, match = e.match;
  // 3. Refine: project the loop side's local map into the query with the RANSAC pose, then optimise.
  geo::SE3 T = out.T_query_w;
  const int inliers = project_and_refine(e, e.query, T, out.counters);
  if (inliers < config_.min_projection_inliers) {
    spdlog::debug("loop candidate {}->{}: {} inliers after refinement, rejected", query, match, inliers);
    out.rejection = LoopRejection::kFewProjectionInliers;
    return;
  }

  // 4. A correction larger than the odometry can have drifted since the match is a look-alike place.
  if (config_.drift.enabled) {
    const Motion path = travelled(e.path_poses);
    const Motion moved = correction(e.query.T_cw, T);
    if (!plausible(moved, path, config_.drift)) {
      const Motion allowed = allowance(path, config_.drift);
      spdlog::info(
          "loop candidate {}->{} rejected: it would move the keyframe {:.2f} m / {:.1f} deg, more than drift "
          "allows after {:.1f} m / {:.0f} deg travelled ({:.2f} m / {:.1f} deg)",
          query, match, moved.metres, moved.degrees, path.metres, path.degrees, allowed.metres,
          allowed.degrees);
      out.rejection = LoopRejection::kDrift;
      return;
    }
  }

  // 5. The same correction must hold for the query's neighbours: each keeps its pose relative to the
  // query and must see the loop side's points where the corrected pose puts them.
  if (config_.verify_neighbours > 0) {
    int confirmed = 0;
    const int tried = static_cast<int>(e.neighbours.size());
    for (const LoopEvidence::View& n : e.neighbours) {
      geo::SE3 T_n = n.T_cw * e.query.T_cw.inverse() * T;
      if (project_and_refine(e, n, T_n, out.counters) >= config_.neighbour_min_inliers) ++confirmed;
    }
    if (tried > 0 && 2 * confirmed < tried) {
      spdlog::debug("loop candidate {}->{}: confirmed by {} of {} neighbours, rejected", query, match,
                    confirmed, tried);
      out.rejection = LoopRejection::kNeighbours;
      return;
    }
  }
  out.T_query_w = T;
  out.inliers = inliers;
}

int LoopVerifier::project_and_refine(const LoopEvidence& e, const LoopEvidence::View& kf, geo::SE3& T_cw,
                                     track::PointCounterUpdates& counters) const {
  track::Frame frame;
  frame.features = kf.features;
  frame.grid = map::make_feature_grid(frame.features.keypoints, camera_.width, camera_.height);
  frame.reset_matches();
  frame.T_cw = T_cw;
  frame.has_pose = true;
  track::match_local_points(e.points, frame, e.local_points, 3.0,
                            track::MatchContext{camera_, pyramid_, depth_.bf}, counters);
  std::vector<opt::PoseObservation> obs;
  for (std::size_t i = 0; i < frame.points.size(); ++i) {
    if (frame.points[i] == map::kNoPoint) continue;
    const auto& kp = frame.features.keypoints[i];
    obs.push_back({e.points.live_point(frame.points[i])->position,
                   {kp.pt.x, kp.pt.y},
                   frame.features.u_right[i],
                   pyramid_.inv_level_sigma2[static_cast<std::size_t>(kp.octave)]});
  }
  if (obs.size() < 3) return 0;
  const auto result = opt::optimize_pose(
      T_cw, obs, opt::CameraModel{camera_.fx, camera_.fy, camera_.cx, camera_.cy, depth_.bf},
      opt::PoseOptimizerConfig{});
  return result.inliers;
}

}  // namespace sp::loop
