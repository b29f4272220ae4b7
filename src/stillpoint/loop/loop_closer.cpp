#include "stillpoint/loop/loop_closer.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <unordered_map>
#include <unordered_set>

#include "stillpoint/common/error.hpp"
#include "stillpoint/common/timing.hpp"
#include "stillpoint/loop/pose_graph_correction.hpp"
#include "stillpoint/optimize/pose_graph.hpp"
#include "stillpoint/tracking/projection_matcher.hpp"

namespace sp::loop {

LoopClosingConfig LoopClosingConfig::from_yaml(const ConfigReader& r) {
  LoopClosingConfig c;
  r.read_choice("detector", c.detector, {"off", "bow-keyframe", "bow-sequence", "netvlad", "hybrid"});
  r.read("place_model", c.place_model);
  r.read("vocabulary", c.vocabulary);
  c.detection = LoopDetectorParams::from_yaml(r.section("detection"));
  if (r.has("sequence_trigger")) {
    if (r.section("detection").section("sequence").has("trigger")) {
      r.fail("sequence_trigger", "set either this or detection.sequence.trigger, not both");
    }
    r.read_choice("sequence_trigger", c.detection.sequence.trigger, {"rising-edge", "level"});
  }
  r.read("min_keyframes", c.min_keyframes, std::size_t{2}, std::size_t{10000});
  r.read("min_descriptor_matches", c.verification.min_descriptor_matches, 3, 10000);
  r.read("ransac_threshold_m", c.verification.ransac_threshold_m, 0.001, 1.0);
  r.read("min_ransac_inliers", c.verification.min_ransac_inliers, 3, 10000);
  r.read("min_projection_inliers", c.verification.min_projection_inliers, 3, 10000);
  r.read("verify_neighbours", c.verification.verify_neighbours, 0, 50);
  r.read("neighbour_min_inliers", c.verification.neighbour_min_inliers, 3, 10000);
  r.read("drift_check", c.verification.drift.enabled);
  r.read("max_correction_m", c.verification.drift.base_m, 0.0, 1000.0);
  r.read("max_correction_deg", c.verification.drift.base_deg, 0.0, 180.0);
  r.read("max_correction_ratio", c.verification.drift.ratio, 0.0, 10.0);
  r.read("global_ba", c.global_ba);
  r.read("global_ba_iterations", c.global_ba_iterations, 1, 1000);
  return c;
}

namespace {

// The covisibility graph as the detectors see it; takes the map lock per call.
class MapCovisibility final : public CovisibilityView {
 public:
  explicit MapCovisibility(map::Map& map) : map_(map) {}
  [[nodiscard]] std::vector<KeyframeId> covisible(KeyframeId id, int n_best) const override {
    map::MapView view = map_.view();
    return view.best_covisibles(
        id, n_best <= 0 ? std::numeric_limits<std::size_t>::max() : static_cast<std::size_t>(n_best));
  }

 private:
  map::Map& map_;
};

}  // namespace

LoopCloser::LoopCloser(map::Map& map, LoopClosingConfig config, std::shared_ptr<const Vocabulary> vocabulary,
                       geo::CameraIntrinsics camera, track::DepthModel depth, map::ScalePyramid pyramid,
                       bool deterministic)
    : map_(map),
      config_(std::move(config)),
      vocabulary_(std::move(vocabulary)),
      camera_(camera),
      depth_(depth),
      pyramid_(std::move(pyramid)),
      deterministic_(deterministic),
      verifier_(config_.verification, camera_, depth_, pyramid_) {
  if (config_.detector != "off" && vocabulary_ != nullptr) {
    detector_ = make_loop_detector(config_.detector, config_.detection);
  }
}

LoopCloser::~LoopCloser() {
  abort_global_ba_ = true;
  finish();
}

void LoopCloser::finish() {
  if (global_ba_thread_.joinable()) global_ba_thread_.join();
}

void LoopCloser::flush() {
  if (!detector_) return;
  // The last open keyframe sequence is only queried now (a path that ends where it started).
  Stopwatch watch;
  const MapCovisibility covisibility(map_);
  const auto candidates = detector_->finish(covisibility);
  {
    std::lock_guard lock(stats_mutex_);
    stats_.detection_ms_total += watch.elapsed_ms();
    stats_.candidates += candidates.size();
  }
  map::KeyframeId last;
  {
    map::MapView view = map_.view();
    const auto ids = view.keyframe_ids_sorted();
    if (!ids.empty()) last = ids.back();
  }
  handle_candidates(candidates, last);
  finish();
}

LoopClosingStats LoopCloser::stats() const {
  std::lock_guard lock(stats_mutex_);
  LoopClosingStats s = stats_;
  if (detector_) {
    const DetectorStats d = detector_->stats();
    s.queries = d.queries;
    s.vetoed_by_descriptor = d.vetoed_by_descriptor;
    s.undescribed_candidates = d.undescribed_candidates;
  }
  return s;
}

void LoopCloser::add_existing_keyframes(const std::vector<KeyframeInfo>& keyframes) {
  if (!detector_) return;
  for (KeyframeInfo kf : keyframes) {
    // A loaded map's keyframes keep their thumbnails: describe them, or the learned detectors could
    // never close a loop against the loaded map (netvlad ignores them, hybrid cannot re-rank them).
    if (needs_global_descriptors() && describe_ && kf.global.size() == 0) {
      cv::Mat thumbnail;
      {
        map::MapView view = map_.view();
        const map::Keyframe* k = view.keyframe(kf.id);
        if (k != nullptr && !k->bad) thumbnail = k->thumbnail.clone();
      }
      if (!thumbnail.empty()) kf.global = describe_(thumbnail);
    }
    detector_->add_keyframe(kf);
  }
}

void LoopCloser::erase_keyframes(const std::vector<map::KeyframeId>& keyframes) {
  if (!detector_) return;
  for (map::KeyframeId id : keyframes) detector_->erase_keyframe(id);
}

void LoopCloser::process(map::KeyframeId kid) {
  if (!detector_) return;
  KeyframeInfo info;
  std::size_t keyframes = 0;
  cv::Mat descriptors;
  cv::Mat thumbnail;
  {
    map::MapView view = map_.view();
    const map::Keyframe* kf = view.keyframe(kid);
    if (kf == nullptr || kf->bad) return;
    info.id = kid;
    info.R_cw = kf->T_cw.rotation();
    keyframes = view.live_keyframes();
    descriptors = kf->features.descriptors.clone();
    if (needs_global_descriptors()) thumbnail = kf->thumbnail.clone();
  }
  double global_ms = 0;
  if (needs_global_descriptors()) {
    if (!describe_)
      throw Error("loop detector '" + detector_->name() + "' needs a place model (set_global_describer)");
    if (thumbnail.empty())
      throw Error("loop detector '" + detector_->name() + "': keyframe " + std::to_string(kid.value()) +
                  " has no thumbnail");
    Stopwatch global_watch;
    info.global = describe_(thumbnail);
    global_ms = global_watch.elapsed_ms();
  }
  // The BoW vector is the keyframe's description, shared by every detector (ORB-SLAM computes it in
  // local mapping); it is timed apart from detection, which is the database search itself.
  Stopwatch bow_watch;
  info.bow = vocabulary_->transform(descriptors);
  const double bow_ms = bow_watch.elapsed_ms();
  std::vector<LoopCandidate> candidates;
  const MapCovisibility covisibility(map_);
  Stopwatch watch;
  // Right after a loop, or on a small map, the keyframe is only filed.
  if (keyframes < config_.min_keyframes ||
      (last_loop_keyframe_ != map::kNoKeyframe && kid.value() < last_loop_keyframe_.value() + 10)) {
    detector_->add_keyframe(info);
  } else {
    candidates = detector_->detect(info, covisibility);
  }
  {
    std::lock_guard lock(stats_mutex_);
    stats_.keyframes++;
    stats_.detection_ms_total += watch.elapsed_ms();
    stats_.bow_ms_total += bow_ms;
    stats_.global_ms_total += global_ms;
    stats_.candidates += candidates.size();
  }
  if (filed_) filed_(kid, info.bow);
  handle_candidates(candidates, kid);
}

void LoopCloser::handle_candidates(const std::vector<LoopCandidate>& candidates, map::KeyframeId kid) {
  for (const LoopCandidate& c : candidates) {
    spdlog::debug("loop candidate: keyframe {} -> {} (score {:.3f})", c.query, c.match, c.score);
    auto verified = verify(c.query, c.match);
    if (!verified) continue;
    {
      std::lock_guard lock(stats_mutex_);
      ++stats_.loops_detected;
    }
    spdlog::info("loop detected: keyframe {} revisits keyframe {} ({} inliers)", c.query, c.match,
                 verified->inliers);
    const LoopClosure closure = verified->closure;
    Stopwatch correction;
    if (!correct(std::move(*verified))) continue;
    {
      std::lock_guard lock(stats_mutex_);
      ++stats_.loops_closed;
      stats_.closures.push_back(closure);
      stats_.correction_ms_total += correction.elapsed_ms();
    }
    last_loop_keyframe_ = kid;
    break;
  }
}

std::optional<LoopCloser::VerifiedLoop> LoopCloser::verify(map::KeyframeId query, map::KeyframeId match) {
  Stopwatch watch;
  map::LockHoldClock clock;
  std::optional<LoopEvidence> evidence;
  {
    const map::MapReader view = map_.reader(&clock);
    evidence = gather_evidence(view, query, match);
  }
  if (!evidence) return std::nullopt;
  // Off the lock from here on, except for the loop side's copy and the last view.
  LoopVerification result = verifier_.match_and_align(*evidence);
  if (result.accepted()) {
    bool live = false;
    {
      const map::MapReader view = map_.reader(&clock);
      live = add_loop_side(view, *evidence, config_.verification.verify_neighbours);
    }
    if (live) {
      finish_evidence(*evidence);
      verifier_.refine(*evidence, result);
    } else {
      result.rejection = LoopRejection::kCulled;
    }
  }

  std::optional<VerifiedLoop> loop;
  if (result.accepted() || !result.counters.empty()) {
    map::MapView view = map_.view(&clock);
    result.counters.apply(view);
    // Local mapping may have culled either keyframe while the lock was free.
    const map::Keyframe* q = view.keyframe(query);
    const map::Keyframe* m = view.keyframe(match);
    if (result.accepted() && q != nullptr && !q->bad && m != nullptr && !m->bad) {
      loop.emplace(
          VerifiedLoop{query, match, result.T_query_w, result.inliers,
                       LoopClosure{evidence->query_stamp, evidence->match_stamp,
                                   result.T_query_w * evidence->T_match_cw.inverse(), result.inliers},
                       map::KeyframeHold(map_)});
      // Held until correct() is done with them: local mapping may cull between the two views.
      loop->hold.add(view, query);
      loop->hold.add(view, match);
    }
  }
  const map::LockHoldClock::Times lock = clock.take();
  std::lock_guard stats_lock(stats_mutex_);
  ++stats_.verifications;
  stats_.verification_ms_total += watch.elapsed_ms();
  stats_.verification_lock_ms_total += lock.held_ms;
  if (result.rejection == LoopRejection::kDrift) ++stats_.rejected_by_drift;
  if (result.rejection == LoopRejection::kNeighbours) ++stats_.rejected_by_neighbours;
  return loop;
}

bool LoopCloser::correct(VerifiedLoop loop) {
  const map::KeyframeId query = loop.query, match = loop.match;
  const geo::SE3& T_query_w = loop.T_query_w;
  abort_global_ba_ = true;  // a newer loop makes a running global BA obsolete
  finish();
  abort_global_ba_ = false;
  map::LockHoldClock clock;
  std::unordered_map<map::KeyframeId, geo::SE3> old_pose;  // before the correction
  std::unordered_map<map::PointId, map::KeyframeId> corrected_by;
  std::set<std::pair<map::KeyframeId, map::KeyframeId>> loop_links;
  EssentialGraph graph;
  std::uint64_t changes_after_move = 0;
  {
    map::MapView view = map_.view(&clock);
    map::Keyframe* q = view.keyframe(query);
    const map::Keyframe* m = view.keyframe(match);
    if (q == nullptr || q->bad || m == nullptr || m->bad) {
      loop.hold.release(view);
      return false;
    }
    // Poses before the correction: every old edge of the essential graph keeps its relative pose.
    for (map::KeyframeId k : view.keyframe_ids_sorted()) old_pose[k] = view.keyframe(k)->T_cw;

    // 1. Move the query's covisible group rigidly onto the loop side, with its points.
    std::vector<map::KeyframeId> group = view.best_covisibles(query, std::numeric_limits<std::size_t>::max());
    group.push_back(query);
    const geo::SE3 T_wq_old = q->T_cw.inverse();
    std::unordered_map<map::KeyframeId, geo::SE3> corrected;
    for (map::KeyframeId k : group) corrected[k] = view.keyframe(k)->T_cw * T_wq_old * T_query_w;
    // Each point is corrected once per loop, by the first group keyframe that sees it (ORB-SLAM's
    // mnCorrectedByKF); step 4 moves it on with that keyframe, not with its reference keyframe, which
    // may lie outside the group and would move it a second time.
    for (map::KeyframeId k : group) {
      map::Keyframe* kf = view.keyframe(k);
      const geo::SE3 delta = corrected[k].inverse() * kf->T_cw;  // old world -> corrected world
      for (map::PointId pid : kf->points) {
        map::MapPoint* p = pid == map::kNoPoint ? nullptr : view.live_point(pid);
        if (p == nullptr || !corrected_by.emplace(p->id, k).second) continue;
        p->position = delta * p->position;
      }
    }
    for (map::KeyframeId k : group) view.keyframe(k)->T_cw = corrected[k];

    // 2. Fuse the loop side's points into the group: duplicates become one point.
    std::vector<map::KeyframeId> loop_side = view.best_covisibles(match, 10);
    loop_side.push_back(match);
    std::vector<map::PointId> loop_points;
    std::unordered_set<map::PointId> seen;
    for (map::KeyframeId k : loop_side) {
      for (map::PointId pid : view.keyframe(k)->points) {
        if (pid != map::kNoPoint && seen.insert(pid).second) loop_points.push_back(pid);
      }
    }
    std::unordered_map<map::KeyframeId, std::map<map::KeyframeId, int>> links_before;
    for (map::KeyframeId k : group) links_before[k] = view.keyframe(k)->covisibility;
    const track::MatchContext ctx{camera_, pyramid_, depth_.bf};
    for (map::KeyframeId k : group) track::fuse_into_keyframe(view, k, loop_points, 4.0, ctx);
    for (map::KeyframeId k : group) view.update_connections(k);
    view.keyframe(query)->loop_edges.insert(match);
    view.keyframe(match)->loop_edges.insert(query);
    // Links the fusion made between the group and the rest of the map (ORB-SLAM's LoopConnections):
    // they are the loop, so the pose graph measures them with the corrected poses. With the poses from
    // before the correction they would hold the drift the loop is closing (before 2026-12-02 they did).
    for (map::KeyframeId k : group) {
      for (const auto& [other, w] : view.keyframe(k)->covisibility) {
        if (links_before[k].contains(other) || std::find(group.begin(), group.end(), other) != group.end())
          continue;
        loop_links.insert(std::minmax(k, other));
      }
    }
    // 3a. The essential graph is copied; the map is consistent again (the group sits on the loop side,
    // the rest waits for the pose graph), so tracking and local mapping go on while it is solved.
    graph = essential_graph(view, query, match, old_pose, loop_links);
    map_.notify_big_change();  // frames and local BAs that read the map before the move are dropped
    changes_after_move = map_.big_change_count();
  }

  // 3b. The pose graph, off the lock.
  Stopwatch solve_watch;
  opt::optimize_pose_graph(graph.vertices, graph.edges, opt::PoseGraphConfig{});
  double solve_ms = solve_watch.elapsed_ms();

  std::uint64_t changes = 0;
  {
    map::MapView view = map_.view(&clock);
    if (map_.big_change_count() != changes_after_move) {
      // Another correction (a map merge by the tracker) moved keyframes meanwhile: the solution
      // no longer fits the map, so the graph is solved again from the map as it is, under the lock.
      Stopwatch again;
      graph = essential_graph(view, query, match, old_pose, loop_links);
      opt::optimize_pose_graph(graph.vertices, graph.edges, opt::PoseGraphConfig{});
      solve_ms += again.elapsed_ms();
    }
    // 3c. Keyframes and points take their corrections.
    apply_pose_graph(view, graph, corrected_by, pyramid_);
    map_.notify_big_change();
    changes = map_.big_change_count();
    loop.hold.release(view);
  }
  const map::LockHoldClock::Times lock = clock.take();
  {
    std::lock_guard stats_lock(stats_mutex_);
    stats_.pose_graph_ms_total += solve_ms;
    stats_.correction_lock_ms_total += lock.held_ms;
  }
  if (config_.global_ba) start_global_ba(changes);
  return true;
}

void LoopCloser::start_global_ba(std::uint64_t changes_at_start) {
  if (deterministic_) {
    run_global_ba(changes_at_start);
  } else {
    global_ba_thread_ = std::thread([this, changes_at_start] { run_global_ba(changes_at_start); });
  }
}

void LoopCloser::run_global_ba(std::uint64_t changes_at_start) {
  opt::BAProblem problem;
  {
    map::MapView view = map_.view();
    const auto ids = view.keyframe_ids_sorted();
    // Each map's root fixes its gauge (maps not merged yet share nothing).
    std::vector<map::KeyframeId> roots;
    for (map::MapId m : view.live_maps()) roots.push_back(view.map_root(m));
    for (map::KeyframeId k : ids) {
      const bool root = std::find(roots.begin(), roots.end(), k) != roots.end();
      problem.keyframes.push_back({k.value(), view.keyframe(k)->T_cw, k == ids.front() || root});
    }
    std::vector<map::PointId> pids;
    for (const auto& [pid, p] : view.points()) {
      if (!p.bad) pids.push_back(pid);
    }
    std::sort(pids.begin(), pids.end());
    for (map::PointId pid : pids) {
      const map::MapPoint* p = view.point(pid);
      problem.points.push_back({pid.value(), p->position});
      for (const auto& [k, feature] : p->observations) {
        const map::Keyframe* kf = view.keyframe(k);
        if (kf == nullptr || kf->bad) continue;
        const auto& kp = kf->features.keypoints[static_cast<std::size_t>(feature)];
        problem.observations.push_back({k.value(),
                                        pid.value(),
                                        {kp.pt.x, kp.pt.y},
                                        kf->features.u_right[static_cast<std::size_t>(feature)],
                                        pyramid_.inv_level_sigma2[static_cast<std::size_t>(kp.octave)]});
      }
    }
  }
  opt::BAConfig cfg;
  cfg.iterations_first = config_.global_ba_iterations;
  cfg.iterations_second = config_.global_ba_iterations;
  const auto result = opt::run_bundle_adjustment(
      problem, opt::CameraModel{camera_.fx, camera_.fy, camera_.cx, camera_.cy, depth_.bf}, cfg,
      &abort_global_ba_);
  std::lock_guard stats_lock(stats_mutex_);
  ++stats_.global_ba_runs;
  if (result.aborted) {
    ++stats_.global_ba_aborted;
    return;
  }
  map::MapView view = map_.view();
  if (map_.big_change_count() != changes_at_start) return;  // another correction happened meanwhile
  // BA's poses replace the current ones; keyframes added while BA ran follow their parent's change.
  KeyframeMoves change;
  for (const auto& k : problem.keyframes) {
    if (const map::Keyframe* kf = view.keyframe(map::KeyframeId{k.id}); kf != nullptr)
      change.emplace(map::KeyframeId{k.id}, std::pair{kf->T_cw, k.T_cw});
  }
  move_keyframes(view, change);
  std::unordered_set<map::PointId> optimised;
  for (const auto& p : problem.points) {
    if (map::MapPoint* mp = view.point(map::PointId{p.id}); mp != nullptr && !mp->bad) {
      mp->position = p.p_w;
      optimised.insert(map::PointId{p.id});
    }
  }
  move_points(view, change, [&optimised](map::PointId pid, const map::MapPoint& p) {
    return optimised.contains(pid) ? map::kNoKeyframe : p.reference;
  });
  map_.notify_big_change();
  spdlog::info("global BA done: {} keyframes, {} points", problem.keyframes.size(), problem.points.size());
}

}  // namespace sp::loop
