#include "stillpoint/mapping/local_mapper.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <set>
#include <unordered_map>
#include <unordered_set>

#include "stillpoint/common/timing.hpp"
#include "stillpoint/optimize/ba_conditioning.hpp"
#include "stillpoint/tracking/projection_matcher.hpp"

namespace sp::mapping {

LocalMappingConfig LocalMappingConfig::from_yaml(const ConfigReader& r) {
  LocalMappingConfig c;
  r.read("fusion_neighbours", c.fusion_neighbours, std::size_t{0}, std::size_t{100});
  r.read("fusion_radius", c.fusion_radius, 0.5, 50.0);
  r.read("local_ba", c.local_ba);
  r.read("ba_max_keyframes", c.ba_max_keyframes, std::size_t{2}, std::size_t{200});
  r.read("ba_max_keyframe_move_m", c.ba_max_keyframe_move_m, 0.0, 10.0);
  r.read("ba_weak_keyframe_std_m", c.ba_weak_keyframe_std_m, 0.0, 10.0);
  r.read("redundancy", c.redundancy, 0.5, 1.0);
  r.read("cull_keyframes", c.cull_keyframes);
  r.read("min_found_ratio", c.min_found_ratio, 0.0, 1.0);
  r.read("min_weighted_observations", c.min_weighted_observations, 1, 100);
  r.read("purge_after_keyframes", c.purge_after_keyframes, std::size_t{1}, std::size_t{100000});
  c.ba = opt::BAConfig::from_yaml(r.section("bundle_adjustment"));
  c.triangulation = TriangulationConfig::from_yaml(r.section("triangulation"));
  return c;
}

LocalMapper::LocalMapper(map::Map& map, LocalMappingConfig config, geo::CameraIntrinsics camera,
                         track::DepthModel depth, map::ScalePyramid pyramid)
    : map_(map),
      config_(std::move(config)),
      camera_(camera),
      depth_(depth),
      pyramid_(std::move(pyramid)),
      camera_model_{camera.fx, camera.fy, camera.cx, camera.cy, depth.bf},
      triangulator_(config_.triangulation, camera, depth.bf, pyramid_) {}

LocalMappingStats LocalMapper::process(map::KeyframeId kid, const std::atomic<bool>* abort) {
  LocalMappingStats stats;
  {
    map::MapView view = map_.view();
    if (view.keyframe(kid) == nullptr || view.keyframe(kid)->bad) return stats;
    integrate(view, kid);
    stats.culled_points = cull_recent_points(view, kid);
  }
  if (config_.triangulation.enabled) {
    Stopwatch watch;
    stats.triangulated_points = create_new_points(kid);
    stats.triangulation_ms = watch.elapsed_ms();
  }
  {
    map::MapView view = map_.view();
    if (view.keyframe(kid) == nullptr || view.keyframe(kid)->bad) return stats;
    stats.fused_points = fuse_neighbours(view, kid);
  }
  if (config_.local_ba) local_bundle_adjustment(kid, abort, stats);
  map::MapView view = map_.view();
  if (config_.cull_keyframes) stats.culled_keyframes = cull_keyframes(view, kid);
  if (kid.value() > config_.purge_after_keyframes)
    stats.purged_records = view.purge_bad(map::KeyframeId{kid.value() - config_.purge_after_keyframes});
  return stats;
}

void LocalMapper::integrate(map::MapView& view, map::KeyframeId kid) {
  const map::Keyframe* kf = view.keyframe(kid);
  for (map::PointId pid : kf->points) {
    if (pid == map::kNoPoint) continue;
    const map::MapPoint* p = view.point(pid);
    if (p == nullptr || p->bad) continue;
    view.update_point_normal_and_depth(pid, pyramid_);
    view.update_point_descriptor(pid);
    if (p->first_keyframe == kid) recent_points_.push_back(pid);
  }
  view.update_connections(kid);
}

int LocalMapper::cull_recent_points(map::MapView& view, map::KeyframeId kid) {
  int culled = 0;
  std::vector<map::PointId> keep;
  for (map::PointId pid : recent_points_) {
    map::MapPoint* p = view.point(pid);
    if (p == nullptr || p->bad) continue;
    // Keyframe ids grow by one per keyframe, so the id gap counts keyframes since the point's birth.
    const auto age = kid.value() - p->first_keyframe.value();
    // Two keyframes after its birth a point must have been seen again: weighted observations count a
    // view with depth twice, so 3 = its own depth view plus one more, or three views without depth.
    if (p->found_ratio() < config_.min_found_ratio ||
        (age >= 2 && view.weighted_observations(*p) < config_.min_weighted_observations)) {
      view.erase_point(pid);
      ++culled;
    } else if (age < 3) {
      keep.push_back(pid);
    }
  }
  recent_points_ = std::move(keep);
  return culled;
}

int LocalMapper::create_new_points(map::KeyframeId kid) {
  struct Snapshot {
    map::KeyframeId id;
    map::FeatureSet features;  // descriptors share the keyframe's (immutable) buffer
    TriangulationView view;
  };
  std::vector<Snapshot> snaps;
  {
    map::MapView view = map_.view();
    std::vector<map::KeyframeId> ids{kid};
    for (map::KeyframeId n : view.best_covisibles(kid, config_.triangulation.neighbours)) ids.push_back(n);
    snaps.reserve(ids.size());
    for (map::KeyframeId id : ids) {
      const map::Keyframe* kf = view.keyframe(id);
      if (kf == nullptr || kf->bad || kf->features.size() != kf->points.size()) continue;
      Snapshot& s = snaps.emplace_back(Snapshot{id, kf->features, {}});
      s.view.T_cw = kf->T_cw;
      s.view.free.resize(kf->points.size());
      for (std::size_t i = 0; i < kf->points.size(); ++i) {
        const map::MapPoint* p = kf->points[i] == map::kNoPoint ? nullptr : view.live_point(kf->points[i]);
        s.view.free[i] = p == nullptr;
      }
    }
  }
  if (snaps.size() < 2 || snaps.front().id != kid) return 0;
  for (Snapshot& s : snaps) s.view.features = &s.features;

  struct NewPoint {
    map::KeyframeId other;
    TriangulatedPoint point;
  };
  std::vector<NewPoint> found;
  TriangulationView& first = snaps.front().view;
  for (std::size_t k = 1; k < snaps.size(); ++k) {
    const std::vector<TriangulatedPoint> pair_points = triangulator_.triangulate(first, snaps[k].view);
    if (spdlog::should_log(spdlog::level::debug)) {
      spdlog::debug("triangulation: keyframe {} with {}: {} free / {} free features, {} new points", kid,
                    snaps[k].id, std::count(first.free.begin(), first.free.end(), true),
                    std::count(snaps[k].view.free.begin(), snaps[k].view.free.end(), true),
                    pair_points.size());
    }
    for (const TriangulatedPoint& p : pair_points) {
      first.free[static_cast<std::size_t>(p.feature1)] = false;  // best covisibles claim features first
      found.push_back({snaps[k].id, p});
    }
  }

  int created = 0;
  map::MapView view = map_.view();
  for (const NewPoint& n : found) {
    map::Keyframe* kf1 = view.keyframe(kid);
    map::Keyframe* kf2 = view.keyframe(n.other);
    if (kf1 == nullptr || kf1->bad || kf2 == nullptr || kf2->bad) continue;
    const auto i1 = static_cast<std::size_t>(n.point.feature1);
    const auto i2 = static_cast<std::size_t>(n.point.feature2);
    // Tracking or fusion may have matched either feature since the copy.
    if (kf1->points[i1] != map::kNoPoint || kf2->points[i2] != map::kNoPoint) continue;
    map::MapPoint p;
    p.position = n.point.position;
    p.descriptor = kf1->features.descriptors.row(n.point.feature1).clone();
    p.reference = kid;
    p.first_keyframe = kid;
    const map::PointId pid = view.add_point(std::move(p));
    view.add_observation(pid, kid, n.point.feature1);
    view.add_observation(pid, n.other, n.point.feature2);
    view.update_point_descriptor(pid);
    view.update_point_normal_and_depth(pid, pyramid_);
    recent_points_.push_back(pid);
    ++created;
  }
  return created;
}

int LocalMapper::fuse_neighbours(map::MapView& view, map::KeyframeId kid) {
  std::vector<map::KeyframeId> targets;
  std::set<map::KeyframeId> seen{kid};
  for (map::KeyframeId n : view.best_covisibles(kid, config_.fusion_neighbours)) {
    if (seen.insert(n).second) targets.push_back(n);
  }
  const std::size_t first = targets.size();
  for (std::size_t k = 0; k < first; ++k) {
    for (map::KeyframeId n2 : view.best_covisibles(targets[k], 5)) {
      if (seen.insert(n2).second) targets.push_back(n2);
    }
  }
  int fused = 0;
  const track::MatchContext ctx{camera_, pyramid_, depth_.bf};
  std::vector<map::PointId> own;
  for (map::PointId pid : view.keyframe(kid)->points) {
    if (pid != map::kNoPoint) own.push_back(pid);
  }
  for (map::KeyframeId t : targets)
    fused += track::fuse_into_keyframe(view, t, own, config_.fusion_radius, ctx);
  std::vector<map::PointId> theirs;
  std::unordered_set<map::PointId> uniq;
  for (map::KeyframeId t : targets) {
    for (map::PointId pid : view.keyframe(t)->points) {
      if (pid != map::kNoPoint && uniq.insert(pid).second) theirs.push_back(pid);
    }
  }
  fused += track::fuse_into_keyframe(view, kid, theirs, config_.fusion_radius, ctx);
  for (map::PointId pid : view.keyframe(kid)->points) {
    if (pid == map::kNoPoint) continue;
    view.update_point_descriptor(pid);
    view.update_point_normal_and_depth(pid, pyramid_);
  }
  view.update_connections(kid);
  return fused;
}

bool LocalMapper::local_bundle_adjustment(map::KeyframeId kid, const std::atomic<bool>* abort,
                                          LocalMappingStats& stats) {
  opt::BAProblem problem;
  std::unordered_set<map::KeyframeId> local;
  {
    map::MapView view = map_.view();
    std::vector<map::KeyframeId> local_ids{kid};
    for (map::KeyframeId n : view.best_covisibles(kid, config_.ba_max_keyframes - 1)) local_ids.push_back(n);
    local.insert(local_ids.begin(), local_ids.end());
    std::unordered_set<map::PointId> points;
    for (map::KeyframeId k : local_ids) {
      for (map::PointId pid : view.keyframe(k)->points) {
        const map::MapPoint* p = pid == map::kNoPoint ? nullptr : view.point(pid);
        if (p != nullptr && !p->bad) points.insert(pid);
      }
    }
    if (points.empty()) return false;
    std::unordered_set<map::KeyframeId> fixed;
    std::vector<map::PointId> sorted_points(points.begin(), points.end());
    std::sort(sorted_points.begin(), sorted_points.end());  // deterministic problem order
    for (map::PointId pid : sorted_points) {
      const map::MapPoint* p = view.point(pid);
      problem.points.push_back({pid.value(), p->position});
      for (const auto& [k, feature] : p->observations) {
        const map::Keyframe* kf = view.keyframe(k);
        if (kf == nullptr || kf->bad) continue;
        if (!local.contains(k)) fixed.insert(k);
        const auto& kp = kf->features.keypoints[static_cast<std::size_t>(feature)];
        opt::BAObservation o;
        o.keyframe_id = k.value();
        o.point_id = pid.value();
        o.uv = {kp.pt.x, kp.pt.y};
        o.u_right = kf->features.u_right[static_cast<std::size_t>(feature)];
        o.inv_sigma2 = pyramid_.inv_level_sigma2[static_cast<std::size_t>(kp.octave)];
        problem.observations.push_back(o);
      }
    }
    std::vector<map::KeyframeId> kf_ids(local.begin(), local.end());
    kf_ids.insert(kf_ids.end(), fixed.begin(), fixed.end());
    std::sort(kf_ids.begin(), kf_ids.end());
    // Each map's first keyframe anchors its gauge (a map started after a loss has its own).
    const map::KeyframeId root = view.map_root(view.keyframe(kid)->map_id);
    for (map::KeyframeId k : kf_ids) {
      // The first keyframe anchors the gauge.
      problem.keyframes.push_back({k.value(), view.keyframe(k)->T_cw, fixed.contains(k) || k == root});
    }
  }
  if (problem.keyframes.size() < 2) return false;
  if (config_.ba_weak_keyframe_std_m > 0.0) {
    const std::vector<double> centre_std = opt::keyframe_centre_std(problem, camera_model_);
    for (std::size_t i = 0; i < problem.keyframes.size(); ++i) {
      if (problem.keyframes[i].fixed || centre_std[i] <= config_.ba_weak_keyframe_std_m) continue;
      problem.keyframes[i].fixed = true;
      ++stats.ba_held_keyframes;
      spdlog::debug("local BA at keyframe {}: keyframe {} held at its pose (centre std {:.1f} cm)", kid,
                    problem.keyframes[i].id, 100.0 * centre_std[i]);
    }
  }
  // A loop correction while BA runs makes its result stale: then it is dropped.
  const std::uint64_t changes_before = map_.big_change_count();
  std::vector<Eigen::Vector3d> centres_before;  // where each keyframe was before BA, for its largest move
  centres_before.reserve(problem.keyframes.size());
  for (const auto& k : problem.keyframes) centres_before.push_back(k.T_cw.inverse().translation());
  Stopwatch watch;
  const opt::BAResult result = opt::run_bundle_adjustment(problem, camera_model_, config_.ba, abort);
  stats.ba_ms = watch.elapsed_ms();
  stats.ba_aborted = result.aborted;
  if (result.aborted) return false;
  // Outside the map lock: how far BA carried a keyframe (fixed ones stay put).
  double largest_move_m = 0.0;
  std::uint64_t moved_most = 0;
  for (std::size_t i = 0; i < problem.keyframes.size(); ++i) {
    const double move = (problem.keyframes[i].T_cw.inverse().translation() - centres_before[i]).norm();
    if (move > largest_move_m) largest_move_m = move, moved_most = problem.keyframes[i].id;
  }
  stats.ba_solved = true;
  stats.ba_largest_keyframe_move_m = largest_move_m;
  spdlog::debug("local BA at keyframe {}: {} keyframes, {} points; keyframe {} moved most, {:.1f} cm", kid,
                problem.keyframes.size(), problem.points.size(), moved_most, 100.0 * largest_move_m);
  if (config_.ba_max_keyframe_move_m > 0.0 && largest_move_m > config_.ba_max_keyframe_move_m) {
    stats.ba_dropped = true;
    return false;
  }

  map::MapView view = map_.view();
  if (map_.big_change_count() != changes_before) return false;
  for (std::size_t i = 0; i < problem.observations.size(); ++i) {
    if (!result.outlier[i]) continue;
    const auto& o = problem.observations[i];
    view.erase_observation(map::PointId{o.point_id}, map::KeyframeId{o.keyframe_id});
  }
  for (const auto& k : problem.keyframes) {
    if (k.fixed) continue;
    if (map::Keyframe* kf = view.keyframe(map::KeyframeId{k.id}); kf != nullptr && !kf->bad)
      kf->T_cw = k.T_cw;
  }
  for (const auto& p : problem.points) {
    const map::PointId pid{p.id};
    map::MapPoint* mp = view.point(pid);
    if (mp == nullptr || mp->bad) continue;
    mp->position = p.p_w;
    view.update_point_normal_and_depth(pid, pyramid_);
  }
  return true;
}

int LocalMapper::cull_keyframes(map::MapView& view, map::KeyframeId kid) {
  int culled = 0;
  for (map::KeyframeId k : view.best_covisibles(kid, std::numeric_limits<std::size_t>::max())) {
    map::Keyframe* kf = view.keyframe(k);
    // A held keyframe is in use by loop closing (MapView::hold_keyframe).
    if (kf == nullptr || kf->bad || kf->parent == map::kNoKeyframe || kf->culling_holds > 0) continue;
    int close = 0, redundant = 0;
    for (std::size_t i = 0; i < kf->points.size(); ++i) {
      const map::PointId pid = kf->points[i];
      const map::MapPoint* p = pid == map::kNoPoint ? nullptr : view.point(pid);
      if (p == nullptr || p->bad) continue;
      const float d = kf->features.depth[i];
      if (d <= 0 || d > depth_.close_depth) continue;  // only close points count for RGB-D
      ++close;
      const int level = kf->features.keypoints[i].octave;
      int others = 0;
      for (const auto& [ok, feature] : p->observations) {
        if (ok == k) continue;
        const map::Keyframe* okf = view.keyframe(ok);
        if (okf == nullptr || okf->bad) continue;
        if (okf->features.keypoints[static_cast<std::size_t>(feature)].octave <= level + 1 && ++others >= 3)
          break;
      }
      if (others >= 3) ++redundant;
    }
    if (close > 0 && redundant > config_.redundancy * close && view.erase_keyframe(k)) ++culled;
  }
  return culled;
}

}  // namespace sp::mapping
