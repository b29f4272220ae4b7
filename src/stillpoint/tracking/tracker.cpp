#include "stillpoint/tracking/tracker.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <numeric>
#include <unordered_set>
#include <utility>

#include "stillpoint/tracking/projection_matcher.hpp"

namespace sp::track {

TrackerConfig TrackerConfig::from_yaml(const ConfigReader& r) {
  TrackerConfig c;
  r.read("init_min_features", c.init_min_features, 10, 100000);
  r.read("motion_search_radius", c.motion_search_radius, 1.0, 100.0);
  r.read("min_motion_matches", c.min_motion_matches, 5, 10000);
  r.read("local_search_factor", c.local_search_factor, 0.5, 20.0);
  r.read("min_inliers", c.min_inliers, 5, 10000);
  r.read("min_inliers_after_reloc", c.min_inliers_after_reloc, 5, 10000);
  r.read("max_local_keyframes", c.max_local_keyframes, std::size_t{5}, std::size_t{1000});
  r.read("new_points_min", c.new_points_min, 0, 10000);
  r.read("init_all_depth_points", c.init_all_depth_points);
  r.read("keyframe_all_depth_points", c.keyframe_all_depth_points);
  r.read("relocalization_candidates", c.relocalization_candidates, std::size_t{1}, std::size_t{1000});
  r.read("reloc_pnp_inliers_only", c.reloc_pnp_inliers_only);
  r.read("reloc_agreeing_candidates", c.reloc_agreeing_candidates, 0, 100);
  r.read("merge_agreeing_candidates", c.merge_agreeing_candidates, 0, 100);
  r.read("relocalization_verify_frames", c.relocalization_verify_frames, 0, 300);
  r.read("relocalization_max_step_m", c.relocalization_max_step_m, 0.001, 10.0);
  r.read("relocalization_max_step_deg", c.relocalization_max_step_deg, 0.01, 180.0);
  r.read("motion_break_m", c.motion_break_m, 0.001, 10.0);
  r.read("motion_break_deg", c.motion_break_deg, 0.01, 180.0);
  r.read("new_map_after_lost_frames", c.new_map_after_lost_frames, 0, 100000);
  r.read("young_map_frames", c.young_map_frames, 0, 100000);
  r.read("drop_abandoned_young_maps", c.drop_abandoned_young_maps);
  r.read("merge_search_interval", c.merge_search_interval, 1, 10000);
  r.read("merge_verify_frames", c.merge_verify_frames, 0, 300);
  r.read("merge_verify_misses", c.merge_verify_misses, 0, 300);
  r.read("merge_min_inliers", c.merge_min_inliers, 5, 10000);
  r.read("new_map_seed_motion_frames", c.new_map_seed_motion_frames, 0, 300);
  r.read("new_map_seed_max_frames", c.new_map_seed_max_frames, 0, 100000);
  r.read("still_people_reserve_keyframes", c.still_people_reserve_keyframes, 0, 100);
  r.read("still_people_reserve_max_age_frames", c.still_people_reserve_max_age_frames, 1, 100000);
  r.read("still_people_retry", c.still_people_retry);
  c.pose = opt::PoseOptimizerConfig::from_yaml(r.section("pose_optimizer"));
  c.keyframes = KeyframePolicyConfig::from_yaml(r.section("keyframes"));
  c.guard = PoseGuardConfig::from_yaml(r.section("pose_guard"));
  c.subpixel = AnchorRefinerConfig::from_yaml(r.section("subpixel"));
  c.new_point_motion = NewPointMotionCheckConfig::from_yaml(r.section("new_point_motion"));
  return c;
}

const char* to_string(TrackingState s) {
  switch (s) {
    case TrackingState::NotInitialized:
      return "not_initialized";
    case TrackingState::Ok:
      return "ok";
    case TrackingState::Lost:
      return "lost";
  }
  return "?";
}

Tracker::Tracker(map::Map& map, TrackerConfig config, geo::CameraIntrinsics camera, DepthModel depth,
                 map::ScalePyramid pyramid, double fps)
    : map_(map),
      config_(std::move(config)),
      camera_(camera),
      depth_(depth),
      pyramid_(std::move(pyramid)),
      fps_(fps),
      policy_(make_keyframe_policy(config_.keyframes)),
      camera_model_{camera.fx, camera.fy, camera.cx, camera.cy, depth.bf},
      trusted_motion_(config_.new_map_seed_motion_frames, config_.new_map_seed_max_frames),
      guard_(config_.guard),
      new_point_check_(config_.new_point_motion, camera),
      refiner_(config_.subpixel, camera, pyramid_) {}

void Tracker::start_in_existing_map() {
  // Lost, not NotInitialized: the next frames go through relocalize() and never create a map at
  // the identity, so the loaded map's frame stays the world frame.
  state_ = TrackingState::Lost;
  reference_ = map::kNoKeyframe;
  velocity_.reset();
  refiner_.reset();
  // The file's maps stay apart (their keyframes keep their map ids): all are open, the oldest is
  // current until a relocalisation says where the camera is. Without a trusted pose no new map starts.
  const map::MapReader view = map_.reader();
  open_maps_ = view.live_maps();
  std::sort(open_maps_.begin(), open_maps_.end());
  if (open_maps_.empty()) open_maps_ = {map::kFirstMap};
  current_map_ = open_maps_.front();
  next_map_ = map::to_int(open_maps_.back()) + 1;
}

TrackOutcome Tracker::track(Frame& frame, const MappingStatus& mapping) {
  lock_clock_.take();
  TrackOutcome out = track_frame(frame, mapping);
  last_lock_ = lock_clock_.take();  // every view of the frame has ended here
  return out;
}

TrackOutcome Tracker::track_frame(Frame& frame, const MappingStatus& mapping) {
  TrackOutcome out;
  frame.reset_matches();
  refined_.assign(frame.features.size(), false);
  frame.grid = map::make_feature_grid(frame.features.keypoints, camera_.width, camera_.height);
  snapshot_.reset(refiner_.anchor_ids());
  counters_.clear();

  if (state_ == TrackingState::NotInitialized) {
    {
      map::MapView view = map_.view(&lock_clock_);
      if (initialize(view, frame)) {
        state_ = TrackingState::Ok;
        out.new_keyframe = reference_;
        record_pose(frame, view.keyframe(reference_)->T_cw, out);
      }
    }
    if (out.new_keyframe != map::kNoKeyframe) refiner_.set_anchor(out.new_keyframe, frame);
  } else {
    std::uint64_t changes_at_read = 0;  // loop corrections seen when the frame's reads began
    {
      // A short read: the last frame's points, followed through replacements, and their copies.
      map::MapReader view = map_.reader(&lock_clock_);
      refresh_last_frame(view);
      changes_at_read = map_.big_change_count();
    }
    bool ok = false;
    bool by_motion = false;
    std::optional<geo::SE3> predicted;
    if (state_ == TrackingState::Ok && velocity_ && last_frame_.has_pose)
      predicted = *velocity_ * last_frame_.T_cw;
    // While a relocalised pose is verified, the frame must land where its motion says: the
    // constant-velocity prediction, or no motion on the first frame after the relocalisation.
    const bool verifying = state_ == TrackingState::Ok && verify_left_ > 0 && last_frame_.has_pose;
    const geo::SE3 expected = predicted ? *predicted : last_frame_.T_cw;
    const bool motion_expected = velocity_.has_value();
    motion_prior_ = predicted;
    bool relocalized = false;
    why_lost_.clear();
    // Tracked: by the motion model or the reference keyframe, then the local map.
    const auto track_tracked = [&] {
      if (velocity_) ok = by_motion = track_motion_model(frame);
      if (!ok) ok = track_reference_keyframe(frame);
    };
    if (state_ == TrackingState::Ok) {
      track_tracked();
    } else {
      ++reloc_stats_.attempts;
      ok = relocalized = relocalize(frame);
      if (!ok && new_map_due(frame)) {
        start_new_map(frame, out);
        return finish_frame(frame, out);
      }
    }
    if (ok) ok = track_local_map(frame);
    if (!ok && state_ == TrackingState::Ok && release_reserve(frame)) {
      // The last resort: the frame tracks again with the people proven still, which it culled, from
      // scratch (no match of the failed attempt carried over).
      counters_.clear();
      frame.reset_matches();
      refined_.assign(frame.features.size(), false);
      by_motion = false;
      track_tracked();
      if (ok) ok = track_local_map(frame);
      ++reserve_stats_.tracker_releases;
      reserve_stats_.tracker_releases_tracked += ok ? 1 : 0;
      spdlog::debug("frame {}: tracked again with the still people: {}", frame.index,
                    ok ? "tracked" : "lost");
      if (!ok) why_lost_ += " also with the still people;";
    }
    if (ok && relocalized) {
      ++reloc_stats_.poses_found;
      out.relocalized = true;
      reloc_frame_ = frame.index;
      unverified_.clear();
      verify_left_ = config_.relocalization_verify_frames;
      if (verify_left_ == 0) accept_relocalization();
    } else if (verifying) {
      // Tracked the way the verification expects: by the motion model, or by reference without one.
      const bool tracked_as_expected = ok && (by_motion || !motion_expected);
      if (tracked_as_expected && consistent_after_relocalization(frame, expected)) {
        if (--verify_left_ == 0) accept_relocalization();
      } else {
        ++reloc_stats_.rejected_by_consistency;
        const PoseDeviation d = pose_deviation(frame.T_cw, expected);
        spdlog::info(
            "relocalisation at frame {} rejected: frame {} did not track consistently from it ({}, {} "
            "inliers, {:.1f} cm / {:.2f} deg from the {})",
            reloc_frame_, frame.index,
            tracked_as_expected ? "tracked" : (ok ? "tracked by reference" : "not tracked"), frame.matched(),
            100.0 * d.translation_m, d.rotation_deg, predicted ? "prediction" : "last pose");
        verify_left_ = 0;
        unverified_.clear();  // already counted as lost
        ok = false;
      }
    }
    const bool jumped = ok && predicted && guard_pose(frame, *predicted);
    motion_prior_.reset();
    // Guarded: the arguments (frame.matched() counts every feature) are not worth evaluating per frame.
    if (spdlog::should_log(spdlog::level::trace)) {
      spdlog::trace(
          "frame {}: {} by {}, {} inliers, reference keyframe {}, local map {} keyframes / {} points",
          frame.index, ok ? "tracked" : "lost", by_motion ? "motion" : "reference", frame.matched(),
          reference_, local_keyframes_.size(), local_points_.size());
    }

    // Write back: counters and the keyframe decision, then (in a second view, once the keyframe is
    // drafted without the lock) the keyframe. Points or keyframes other stages culled or fused since
    // the reads are resolved again there (or skipped).
    bool make_keyframe = false;
    {
      map::MapView view = map_.view(&lock_clock_);
      counters_.apply(view);
      if (ok) {
        if (predicted && !pose_deviation(frame.T_cw, *predicted)
                              .within(config_.motion_break_m, config_.motion_break_deg)) {
          // A pose found far from the prediction is a jump (carried, replayed frames, a fixed error),
          // not a motion: extrapolated, it would put the next frame as far off again.
          ++motion_breaks_;
          velocity_.reset();
        } else if (last_frame_.has_pose) {
          velocity_ = frame.T_cw * last_frame_.T_cw.inverse();
        }
        state_ = TrackingState::Ok;
        // No keyframe from a pose that is not verified yet.
        if (verify_left_ == 0 && need_keyframe(view, frame, mapping)) {
          if (!jumped) {
            make_keyframe = true;
          } else if (guard_.keyframe_despite_jump(frame.matched(), reference_tracked(view))) {
            ++guard_stats_.keyframes_despite_jump;
            make_keyframe = true;
          } else {
            ++guard_stats_.keyframes_vetoed;
          }
        }
      } else {
        // Once per loss, not on every failed relocalisation after it.
        if (state_ == TrackingState::Ok) spdlog::info("frame {} lost:{}", frame.index, why_lost_);
        state_ = TrackingState::Lost;
        velocity_.reset();
        ++lost_frames_;
        ++lost_streak_;
        pending_merge_.reset();  // a merge is verified on consecutive tracked frames
      }
    }
    if (make_keyframe) {
      KeyframeDraft draft = draft_keyframe(frame, /*check_motion=*/true);
      map::MapView view = map_.view(&lock_clock_);
      if (map_.big_change_count() != changes_at_read) {
        // A loop correction moved the map while this frame was tracked on copies: its pose is in
        // the old frame, so it must not seed a keyframe and points (the next frame will).
        spdlog::debug("frame {}: no keyframe, the map was corrected while it was tracked", frame.index);
      } else {
        out.new_keyframe = create_keyframe(view, frame, std::move(draft), config_.keyframe_all_depth_points);
      }
    }
    if (out.new_keyframe != map::kNoKeyframe) refiner_.set_anchor(out.new_keyframe, frame);
    if (state_ == TrackingState::Ok && frame.has_pose) {
      // Relative to the reference's pose as the frame was tracked against it; a keyframe made just
      // now has the frame's pose.
      const LocalMapSnapshot::Pose* ref = snapshot_.pose(reference_);
      if (out.new_keyframe != map::kNoKeyframe) {
        record_pose(frame, frame.T_cw, out);
      } else if (ref != nullptr) {
        record_pose(frame, ref->T_cw, out);
      } else {
        spdlog::warn("frame {}: reference keyframe {} missing, pose not written", frame.index, reference_);
      }
      // Never in a run with one map (nothing else to find).
      if (open_maps_.size() > 1 && verify_left_ == 0 && lost_streak_ == 0 && merge_search_due(frame.index))
        look_for_other_maps(frame);
    }
  }
  return finish_frame(frame, out);
}

TrackOutcome Tracker::finish_frame(Frame& frame, TrackOutcome& out) {
  out.state = out.verifying ? TrackingState::Lost : state_;
  out.inliers = frame.matched();
  // Outliers are forgotten so the next frame does not project them.
  for (std::size_t i = 0; i < frame.points.size(); ++i) {
    if (frame.outlier[i]) frame.points[i] = map::kNoPoint;
  }
  last_frame_ = frame;
  if (state_ != TrackingState::Ok) last_frame_.has_pose = false;
  return out;
}

void Tracker::record_pose(Frame& frame, const geo::SE3& reference_T_cw, TrackOutcome& out) {
  frame.reference = reference_;
  const TrajectoryEntry entry{frame.index, frame.stamp, reference_, frame.T_cw * reference_T_cw.inverse()};
  if (verify_left_ > 0) {
    unverified_.push_back(entry);
    ++lost_frames_;  // until the verification passes
    ++lost_streak_;
    out.verifying = true;
  } else {
    trajectory_.record(entry);
    lost_streak_ = 0;
    trusted_motion_.add(frame.index, frame.T_cw);
  }
}

bool Tracker::initialize(map::MapView& view, Frame& frame) {
  const auto with_depth =
      std::count_if(frame.features.depth.begin(), frame.features.depth.end(), [](float d) { return d > 0; });
  if (with_depth < config_.init_min_features) return false;
  frame.T_cw = geo::SE3();
  frame.has_pose = true;
  current_map_ = map::kFirstMap;
  open_maps_ = {map::kFirstMap};
  next_map_ = 1;
  ++atlas_stats_.maps_created;
  map_started_frame_ = frame.index;
  reference_ = create_keyframe(view, frame, draft_keyframe(frame), config_.init_all_depth_points);
  spdlog::info("map initialised at frame {} with {} points", frame.index, view.live_points());
  return true;
}

void Tracker::refresh_last_frame(const map::MapReader& view) {
  // Points may have been fused by local mapping: follow replacements (and copy them for matching).
  for (auto& pid : last_frame_.points) {
    if (pid == map::kNoPoint) continue;
    const LocalMapSnapshot::Point* p = snapshot_.add(view, pid);
    pid = p == nullptr ? map::kNoPoint : p->id;
  }
  // After a loop correction or BA the last frame moves with its reference keyframe.
  if (last_frame_.has_pose && !trajectory_.entries().empty()) {
    const TrajectoryEntry& e = trajectory_.entries().back();
    const map::Keyframe* ref = view.keyframe(e.reference);
    if (ref != nullptr && !ref->bad && e.frame_index == last_frame_.index)
      last_frame_.T_cw = e.T_c_ref * ref->T_cw;
  }
  if (map_.big_change_count() != big_changes_seen_) {
    big_changes_seen_ = map_.big_change_count();
    velocity_.reset();  // the old velocity mixes poses from before and after the correction
  }
}

bool Tracker::track_motion_model(Frame& frame) {
  frame.T_cw = *velocity_ * last_frame_.T_cw;
  const MatchContext ctx{camera_, pyramid_, depth_.bf};
  int matches = match_last_frame(snapshot_, frame, last_frame_, config_.motion_search_radius, ctx);
  if (matches < config_.min_motion_matches) {
    frame.reset_matches();
    matches = match_last_frame(snapshot_, frame, last_frame_, 2.0 * config_.motion_search_radius, ctx);
  }
  if (matches < config_.min_motion_matches) {
    why_lost_ += fmt::format(" motion model {} matches;", matches);
    return false;
  }
  frame.has_pose = true;
  const int inliers = optimize_pose(frame);
  if (inliers < 10) why_lost_ += fmt::format(" motion model {} inliers of {} matches;", inliers, matches);
  return inliers >= 10;
}

bool Tracker::track_reference_keyframe(Frame& frame) {
  std::optional<LocalMapSnapshot::Keyframe> ref;
  {
    map::MapReader view = map_.reader(&lock_clock_);
    ref = snapshot_.add_keyframe(view, reference_);
  }
  if (!ref) return false;
  frame.reset_matches();
  const int matches = match_keyframe(*ref, frame, 0.7f);
  if (matches < 15) {
    why_lost_ += fmt::format(" reference keyframe {} matches;", matches);
    return false;
  }
  frame.T_cw = last_frame_.has_pose ? last_frame_.T_cw : ref->T_cw;
  frame.has_pose = true;
  const int inliers = optimize_pose(frame);
  if (inliers < 10)
    why_lost_ += fmt::format(" reference keyframe {} inliers of {} matches;", inliers, matches);
  return inliers >= 10;
}

int Tracker::optimize_pose(Frame& frame) {
  std::vector<opt::PoseObservation> obs;
  std::vector<std::size_t> feature_of;
  for (std::size_t i = 0; i < frame.points.size(); ++i) {
    if (frame.points[i] == map::kNoPoint) continue;
    const LocalMapSnapshot::Point* p = snapshot_.live_point(frame.points[i]);
    if (p == nullptr) {
      frame.points[i] = map::kNoPoint;
      continue;
    }
    const auto& kp = frame.features.keypoints[i];
    opt::PoseObservation o;
    o.point_w = p->position;
    o.uv = {kp.pt.x, kp.pt.y};
    o.u_right = frame.features.u_right[i];
    o.inv_sigma2 = refined_.size() == frame.points.size() && refined_[i] && config_.subpixel.level0_weight
                       ? config_.subpixel.refined_weight
                       : pyramid_.inv_level_sigma2[static_cast<std::size_t>(kp.octave)];
    obs.push_back(o);
    feature_of.push_back(i);
  }
  if (obs.size() < 3) return 0;
  if (config_.subpixel.aligned_only_min > 0 && refined_.size() == frame.points.size()) {
    int aligned = 0;
    for (std::size_t i : feature_of) aligned += refined_[i] ? 1 : 0;
    if (refiner_.aligned_only(snapshot_, frame.T_cw, aligned)) {
      // The unaligned features stay matched but leave this solve.
      refiner_.count_aligned_only_solve();
      std::size_t kept = 0;
      const bool unaligned_tracked = config_.subpixel.aligned_only_unaligned == "tracked";
      for (std::size_t k = 0; k < obs.size(); ++k) {
        if (!refined_[feature_of[k]]) {
          if (unaligned_tracked) frame.outlier[feature_of[k]] = false;
          continue;
        }
        obs[kept] = obs[k];
        feature_of[kept] = feature_of[k];
        ++kept;
      }
      obs.resize(kept);
      feature_of.resize(kept);
    }
  }
  // The whole rule of when the prediction enters the solve (PoseOptimizerConfig::motion_prior_*).
  std::optional<opt::PosePrior> prior;
  const int max_matches = config_.pose.motion_prior_max_matches;
  if (motion_prior_ && config_.pose.has_motion_prior() &&
      (max_matches == 0 || static_cast<int>(obs.size()) < max_matches)) {
    prior = opt::PosePrior{*motion_prior_, config_.pose.motion_prior_m,
                           config_.pose.motion_prior_deg * std::numbers::pi / 180.0};
  }
  const auto result =
      opt::optimize_pose(frame.T_cw, obs, camera_model_, config_.pose, prior ? &*prior : nullptr);
  int inliers = 0;
  for (std::size_t k = 0; k < obs.size(); ++k) {
    frame.outlier[feature_of[k]] = result.outlier[k];
    if (!result.outlier[k]) ++inliers;
  }
  return inliers;
}

void Tracker::update_local_map(const map::MapReader& view, Frame& frame) {
  // Local keyframes: those observing the frame's points, their best covisibles, children and parent.
  // Counted in a hash map (kept for its buckets), then visited by increasing id.
  keyframe_counts_.clear();
  for (std::size_t i = 0; i < frame.points.size(); ++i) {
    if (frame.points[i] == map::kNoPoint || frame.outlier[i]) continue;
    const map::MapPoint* p = view.live_point(frame.points[i]);
    if (p == nullptr) continue;
    for (const auto& [kid, feature] : p->observations) ++keyframe_counts_[kid];
  }
  if (keyframe_counts_.empty()) return;
  std::vector<std::pair<map::KeyframeId, int>> counter(keyframe_counts_.begin(), keyframe_counts_.end());
  std::sort(counter.begin(), counter.end());
  local_keyframes_.clear();
  std::unordered_set<map::KeyframeId> in_local;
  map::KeyframeId best = map::kNoKeyframe;
  int best_count = 0;
  for (const auto& [kid, count] : counter) {
    const map::Keyframe* kf = view.keyframe(kid);
    if (kf == nullptr || kf->bad) continue;
    local_keyframes_.push_back(kid);
    in_local.insert(kid);
    if (count > best_count) {
      best_count = count;
      best = kid;
    }
  }
  const std::size_t direct = local_keyframes_.size();
  for (std::size_t k = 0; k < direct && local_keyframes_.size() < config_.max_local_keyframes; ++k) {
    const map::KeyframeId kid = local_keyframes_[k];
    std::vector<map::KeyframeId> neighbours = view.best_covisibles(kid, 10);
    const map::Keyframe* kf = view.keyframe(kid);
    neighbours.insert(neighbours.end(), kf->children.begin(), kf->children.end());
    if (kf->parent != map::kNoKeyframe) neighbours.push_back(kf->parent);
    for (map::KeyframeId n : neighbours) {
      const map::Keyframe* nkf = view.keyframe(n);
      if (nkf == nullptr || nkf->bad || in_local.contains(n)) continue;
      local_keyframes_.push_back(n);
      in_local.insert(n);
      if (local_keyframes_.size() >= config_.max_local_keyframes) break;
    }
  }
  if (best != map::kNoKeyframe) reference_ = best;
  frame.reference = reference_;
  // Only the slots are copied here; collect_local_points() picks the points without the lock.
  local_slots_.clear();
  for (map::KeyframeId kid : local_keyframes_) {
    const std::vector<map::PointId>& points = view.keyframe(kid)->points;
    local_slots_.insert(local_slots_.end(), points.begin(), points.end());
  }
  local_slots_fresh_ = true;
}

void Tracker::collect_local_points(const Frame& frame) {
  // Without a new local map (no match observed anywhere) the last one is searched again.
  if (!local_slots_fresh_) return;
  local_slots_fresh_ = false;
  local_points_.clear();
  seen_.clear();
  for (std::size_t i = 0; i < frame.points.size(); ++i) {
    if (frame.points[i] != map::kNoPoint) seen_.try_emplace(frame.points[i], 0);
  }
  for (map::PointId pid : local_slots_) {
    if (pid == map::kNoPoint || !seen_.try_emplace(pid, 0).second) continue;
    local_points_.push_back(pid);
  }
}

bool Tracker::track_local_map(Frame& frame) {
  {
    // Two short reads: the local keyframes around the frame's matches, then, once the local points
    // are picked without the lock, their copies and the poses the refiner and the trajectory use.
    // The matches keep the copies made with the last frame or the reference keyframe a moment ago
    // (not copied twice under the lock): one culled since then still serves this frame's pose and is
    // skipped at the write-back; one moved by bundle adjustment meanwhile serves at its older place.
    map::MapReader view = map_.reader(&lock_clock_);
    update_local_map(view, frame);
  }
  collect_local_points(frame);
  {
    map::MapReader view = map_.reader(&lock_clock_);
    snapshot_.copy_points(view, local_points_);
    for (map::KeyframeId anchor : refiner_.anchor_ids()) snapshot_.add_pose(view, anchor);
    snapshot_.add_pose(view, reference_);
  }
  snapshot_.index_copies();
  // Matched points count as seen; the local search marks the rest it projects as visible.
  for (std::size_t i = 0; i < frame.points.size(); ++i) {
    if (frame.points[i] == map::kNoPoint) continue;
    if (frame.outlier[i]) {
      frame.points[i] = map::kNoPoint;
      frame.outlier[i] = false;
      continue;
    }
    if (snapshot_.live_point(frame.points[i]) != nullptr) counters_.visible(frame.points[i]);
  }
  const bool recently_relocalized = frame.index < last_reloc_frame_ + static_cast<std::size_t>(fps_);
  const double factor =
      recently_relocalized ? 2.0 * config_.local_search_factor : config_.local_search_factor;
  match_local_points(snapshot_, frame, local_points_, factor, MatchContext{camera_, pyramid_, depth_.bf},
                     counters_);
  int inliers = optimize_pose(frame);
  if (inliers >= config_.min_inliers && refiner_.refine(snapshot_, frame, refined_) > 0)
    inliers = optimize_pose(frame);
  for (std::size_t i = 0; i < frame.points.size(); ++i) {
    if (frame.points[i] == map::kNoPoint || frame.outlier[i]) continue;
    if (snapshot_.live_point(frame.points[i]) != nullptr) counters_.found(frame.points[i]);
  }
  const int needed =
      recently_relocalized && relocalized_once_ ? config_.min_inliers_after_reloc : config_.min_inliers;
  if (inliers < needed) why_lost_ += fmt::format(" local map {} inliers (needs {});", inliers, needed);
  return inliers >= needed;
}

bool Tracker::guard_pose(Frame& frame, const geo::SE3& predicted_T_cw) {
  if (frame.suspect.size() != frame.points.size()) return false;
  const PoseDeviation before = pose_deviation(frame.T_cw, predicted_T_cw);
  if (!guard_.is_jump(before)) return false;
  int inliers = 0, suspect = 0;
  for (std::size_t i = 0; i < frame.points.size(); ++i) {
    if (frame.points[i] == map::kNoPoint || frame.outlier[i]) continue;
    ++inliers;
    suspect += frame.suspect[i] ? 1 : 0;
  }
  if (!guard_.blames_suspects(inliers, suspect)) return false;
  ++guard_stats_.jumps;
  const geo::SE3 solved = frame.T_cw;
  const std::vector<map::PointId> points = frame.points;
  const std::vector<bool> outlier = frame.outlier;
  for (std::size_t i = 0; i < frame.points.size(); ++i) {
    if (frame.suspect[i]) frame.points[i] = map::kNoPoint;
  }
  frame.T_cw = predicted_T_cw;
  const int kept = optimize_pose(frame);
  const PoseDeviation after = pose_deviation(frame.T_cw, predicted_T_cw);
  if (guard_.accepts_resolve(before, after, kept, config_.min_inliers)) {
    ++guard_stats_.resolved;
    spdlog::debug(
        "pose guard: frame {} jumped {:.1f} cm / {:.2f} deg with {} of {} inliers near objects; "
        "re-solved without them: {:.1f} cm / {:.2f} deg",
        frame.index, before.translation_m * 100, before.rotation_deg, suspect, inliers,
        after.translation_m * 100, after.rotation_deg);
  } else {
    frame.T_cw = solved;
    frame.points = points;
    frame.outlier = outlier;
  }
  return true;
}

int Tracker::reference_tracked(const map::MapReader& view) const {
  // ORB-SLAM's "tracked points" of the reference: seen by 3 keyframes (2 while the map has 2).
  return view.tracked_points(reference_, view.live_keyframes(current_map_) <= 2 ? 2 : 3);
}

bool Tracker::need_keyframe(const map::MapReader& view, const Frame& frame,
                            const MappingStatus& mapping) const {
  KeyframeCandidate c;
  c.frames_since_keyframe = frame.index - last_keyframe_frame_;
  c.fps = fps_;
  c.tracked_inliers = frame.matched();
  c.keyframes_in_map = view.live_keyframes(current_map_);  // the map tracked in (several after a loss)
  c.reference_tracked = reference_tracked(view);
  c.mapping_idle = mapping.idle;
  c.mapping_queue = mapping.queue;
  c.image_width = camera_.width;
  c.image_height = camera_.height;
  const map::Keyframe* ref = view.keyframe(reference_);
  if (ref != nullptr) {
    const PoseDeviation d = pose_deviation(frame.T_cw, ref->T_cw);
    c.reference_translation_m = d.translation_m;
    c.reference_rotation_deg = d.rotation_deg;
  }
  for (std::size_t i = 0; i < frame.features.size(); ++i) {
    const float d = frame.features.depth[i];
    if (d <= 0 || d > depth_.close_depth) continue;
    if (frame.points[i] != map::kNoPoint && !frame.outlier[i]) {
      ++c.close_tracked;
    } else {
      ++c.close_untracked;
    }
  }
  if (policy_->needs_view_changes() && ref != nullptr) {
    const Eigen::Vector3d c_now = frame.camera_center();
    const Eigen::Vector3d c_ref = ref->camera_center();
    const bool from_point_normal = config_.keyframes.effective_reference == "point";
    for (std::size_t i = 0; i < frame.points.size(); ++i) {
      if (frame.points[i] == map::kNoPoint || frame.outlier[i]) continue;
      const map::MapPoint* p = view.live_point(frame.points[i]);
      if (p == nullptr) continue;
      const double angle = from_point_normal ? angle_from_normal_deg(p->position, p->normal, c_now)
                                             : viewing_angle_change_deg(p->position, c_ref, c_now);
      c.view_changes.push_back(
          {frame.features.keypoints[i].pt.x, frame.features.keypoints[i].pt.y, static_cast<float>(angle)});
    }
  }
  return policy_->decide(c);
}

Tracker::KeyframeDraft Tracker::draft_keyframe(const Frame& frame, bool check_motion) const {
  KeyframeDraft d;
  map::Keyframe& kf = d.keyframe;
  kf.map_id = current_map_;
  kf.frame_index = frame.index;
  kf.stamp = frame.stamp;
  kf.T_cw = frame.T_cw;
  kf.features = frame.features;
  kf.index = map::make_feature_grid(kf.features.keypoints, camera_.width, camera_.height);
  kf.thumbnail = frame.thumbnail;
  kf.points.assign(frame.features.size(), map::kNoPoint);
  for (std::size_t i = 0; i < frame.points.size(); ++i) {
    if (frame.points[i] != map::kNoPoint && !frame.outlier[i]) kf.points[i] = frame.points[i];
  }
  d.by_depth.resize(frame.features.size());
  std::iota(d.by_depth.begin(), d.by_depth.end(), 0);
  std::sort(d.by_depth.begin(), d.by_depth.end(),
            [&](std::size_t a, std::size_t b) { return frame.features.depth[a] < frame.features.depth[b]; });
  if (check_motion) d.moved = moved_new_point_candidates(frame, kf.points);
  return d;
}

std::vector<bool> Tracker::moved_new_point_candidates(const Frame& frame,
                                                      const std::vector<map::PointId>& slots) const {
  std::vector<bool> moved(frame.features.size(), false);
  if (!new_point_check_.config().enabled() || !last_frame_.has_pose) return moved;
  std::vector<Eigen::Vector2d> px;
  std::vector<double> depth;
  std::vector<std::size_t> which;
  for (std::size_t i = 0; i < frame.features.size(); ++i) {
    if (frame.features.depth[i] <= 0 || slots[i] != map::kNoPoint) continue;
    px.emplace_back(frame.features.keypoints[i].pt.x, frame.features.keypoints[i].pt.y);
    depth.push_back(frame.features.depth[i]);
    which.push_back(i);
  }
  const std::vector<bool> still = new_point_check_.static_candidates(
      last_frame_.gray, frame.gray, last_frame_.T_cw * frame.T_cw.inverse(), px, depth);
  for (std::size_t k = 0; k < which.size(); ++k) {
    moved[which[k]] = !still[k];
    if (moved[which[k]])
      spdlog::debug("frame {}: no new point at ({:.1f}, {:.1f}), depth {:.2f} m: it moved against the camera",
                    frame.index, px[k].x(), px[k].y(), depth[k]);
  }
  return moved;
}

map::KeyframeId Tracker::create_keyframe(map::MapView& view, Frame& frame, KeyframeDraft draft,
                                         bool all_depth_points) {
  const map::KeyframeId kid = view.add_keyframe(std::move(draft.keyframe));
  map::Keyframe* stored = view.keyframe(kid);

  // RGB-D: new points straight from depth, closest first; all close ones and at least new_points_min.
  const geo::SE3 T_wc = frame.T_cw.inverse();
  int created = 0;
  for (std::size_t i : draft.by_depth) {
    const float d = frame.features.depth[i];
    if (d <= 0) continue;
    if (!all_depth_points && d > depth_.close_depth && created >= config_.new_points_min) break;
    if (stored->points[i] != map::kNoPoint) continue;
    if (i < draft.moved.size() && draft.moved[i]) {
      ++new_points_moving_;
      continue;
    }
    const auto& kp = frame.features.keypoints[i];
    map::MapPoint p;
    p.position = T_wc * camera_.unproject({kp.pt.x, kp.pt.y}, d);
    p.descriptor = frame.features.descriptors.row(static_cast<int>(i)).clone();
    p.reference = kid;
    p.first_keyframe = kid;
    const map::PointId pid = view.add_point(std::move(p));
    view.add_observation(pid, kid, static_cast<int>(i));
    view.update_point_normal_and_depth(pid, pyramid_);
    frame.points[i] = pid;
    frame.outlier[i] = false;
    ++created;
  }
  view.update_connections(kid);
  reference_ = kid;
  last_keyframe_frame_ = frame.index;
  if (config_.still_people_reserve_keyframes > 0 && frame.reserve.size() > 0) {
    reserves_.push_back({kid, frame.index, std::exchange(frame.reserve, {})});  // the frame is done with it
    while (reserves_.size() > static_cast<std::size_t>(config_.still_people_reserve_keyframes))
      reserves_.pop_front();
  }
  return kid;
}

bool Tracker::release_reserve(Frame& frame) {
  if (!config_.still_people_retry) return false;
  // Mapped only now, when the frame cannot be tracked without them: people are a last resort.
  const std::size_t mapped = reserves_.empty() ? 0 : map_reserve(frame);
  if (frame.reserve.size() == 0) return mapped > 0;
  const std::size_t before = frame.features.size();
  map::append(frame.features, frame.reserve);
  // People in use are suspects for the pose guard, as when the motion check releases them.
  frame.suspect.resize(before, false);
  frame.suspect.resize(frame.features.size(), true);
  frame.culled -= std::min(frame.culled, frame.reserve.size());
  frame.reserve = {};
  frame.grid = map::make_feature_grid(frame.features.keypoints, camera_.width, camera_.height);
  return true;
}

std::size_t Tracker::map_reserve(const Frame& frame) {
  map::MapView view = map_.view(&lock_clock_);
  std::size_t points = 0, keyframes = 0;
  for (const Reserve& r : reserves_) {
    if (frame.index > r.frame_index + static_cast<std::size_t>(config_.still_people_reserve_max_age_frames))
      continue;
    const map::Keyframe* kf = view.keyframe(r.keyframe);
    if (kf == nullptr || kf->bad || kf->map_id != current_map_) continue;
    // The keyframe's pose now (bundle adjustment may have moved it since it was made).
    const geo::SE3 T_wc = kf->T_cw.inverse();
    const std::optional<std::size_t> first =
        view.append_features(r.keyframe, r.features, cv::Size(camera_.width, camera_.height));
    if (!first) continue;
    ++keyframes;
    for (std::size_t i = 0; i < r.features.size(); ++i) {
      const float d = r.features.depth[i];
      if (d <= 0) continue;
      const auto& kp = r.features.keypoints[i];
      map::MapPoint p;
      p.position = T_wc * camera_.unproject({kp.pt.x, kp.pt.y}, d);
      p.descriptor = r.features.descriptors.row(static_cast<int>(i)).clone();
      p.reference = r.keyframe;
      p.first_keyframe = r.keyframe;
      const map::PointId pid = view.add_point(std::move(p));
      view.add_observation(pid, r.keyframe, static_cast<int>(*first + i));
      view.update_point_normal_and_depth(pid, pyramid_);
      ++points;
    }
  }
  reserves_.clear();  // mapped, or too old to trust
  if (points > 0) {
    ++reserve_stats_.releases;
    reserve_stats_.points += points;
  }
  spdlog::debug("frame {}: still people released, {} reserve points mapped in {} keyframes", frame.index,
                points, keyframes);
  return points;
}

}  // namespace sp::track
