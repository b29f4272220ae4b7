// The tracker's recovery when tracking is lost (tracker.hpp): global relocalisation and its check over
// the next frames, a new map after a long loss, and merging maps once a frame is found in two
// (docs/robustness.md "Relocalisation", "New maps and merging"). The per-frame path is tracker.cpp.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <opencv2/calib3d.hpp>
#include <unordered_set>

#include "stillpoint/tracking/pose_agreement.hpp"
#include "stillpoint/tracking/projection_matcher.hpp"
#include "stillpoint/tracking/tracker.hpp"

namespace sp::track {

bool Tracker::consistent_after_relocalization(const Frame& frame, const geo::SE3& expected_T_cw) const {
  if (frame.matched() < config_.min_inliers_after_reloc) return false;
  const PoseDeviation d = pose_deviation(frame.T_cw, expected_T_cw);
  return d.translation_m <= config_.relocalization_max_step_m &&
         d.rotation_deg <= config_.relocalization_max_step_deg;
}

void Tracker::accept_relocalization() {
  ++relocalizations_;
  ++reloc_stats_.accepted;
  if (!first_reloc_frame_) first_reloc_frame_ = reloc_frame_;
  for (const TrajectoryEntry& e : unverified_) trajectory_.record(e);
  lost_frames_ -= std::min(lost_frames_, unverified_.size());
  if (!unverified_.empty()) {
    lost_streak_ = 0;
    spdlog::info("relocalisation at frame {} verified over {} frames", reloc_frame_, unverified_.size());
  }
  unverified_.clear();
}

bool Tracker::relocalize(Frame& frame) {
  std::vector<map::KeyframeId> candidates;
  {
    // Candidates: those of the provider (a BoW query over every keyframe of the map) first, then the
    // most recent keyframes and the covisibles of the last reference.
    const map::MapReader view = map_.reader(&lock_clock_);
    std::vector<map::KeyframeId> ids = view.keyframe_ids_sorted();
    for (auto it = ids.rbegin(); it != ids.rend() && candidates.size() < config_.relocalization_candidates;
         ++it) {
      candidates.push_back(*it);
    }
    for (map::KeyframeId k : view.best_covisibles(reference_, 10)) {
      if (std::find(candidates.begin(), candidates.end(), k) == candidates.end()) candidates.push_back(k);
    }
    if (reloc_candidates_) {
      std::vector<map::KeyframeId> first = reloc_candidates_(view, frame);
      for (map::KeyframeId k : candidates) {
        if (std::find(first.begin(), first.end(), k) == first.end()) first.push_back(k);
      }
      candidates = std::move(first);
    }
  }
  const map::KeyframeId kid = locate(frame, candidates, counters_, config_.reloc_agreeing_candidates,
                                     config_.min_inliers_after_reloc);
  if (kid == map::kNoKeyframe) return false;
  reference_ = kid;
  last_reloc_frame_ = frame.index;
  relocalized_once_ = true;
  // Any map's keyframe may relocalise the frame: it then tracks in that map (a map left behind stays
  // open until a later frame sees both).
  map::MapId found_in = current_map_;
  {
    const map::MapReader view = map_.reader(&lock_clock_);
    if (const map::Keyframe* kf = view.keyframe(kid); kf != nullptr) found_in = kf->map_id;
  }
  if (found_in != current_map_) {
    spdlog::info("frame {} relocalised in map {} (was tracking in map {})", frame.index,
                 map::to_int(found_in), map::to_int(current_map_));
    if (config_.drop_abandoned_young_maps && lost_young(frame)) {
      const std::size_t withdrawn = trajectory_.withdraw_from(*map_started_frame_);
      lost_frames_ += withdrawn;
      ++atlas_stats_.young_maps_dropped;
      atlas_stats_.frames_withdrawn += withdrawn;
      spdlog::info("map {} (from frame {}) left young: its {} frames taken back", map::to_int(current_map_),
                   *map_started_frame_, withdrawn);
    }
    map_started_frame_.reset();  // an older map: not young
  }
  current_map_ = found_in;
  pending_merge_.reset();
  spdlog::info("relocalised frame {} against keyframe {}", frame.index, kid);
  return true;
}

map::KeyframeId Tracker::locate(Frame& frame, const std::vector<map::KeyframeId>& candidates,
                                PointCounterUpdates& counters, int agreeing_candidates, int min_inliers) {
  // The first pose found, kept while further candidates are asked whether they agree with it.
  struct Found {
    map::KeyframeId keyframe;
    geo::SE3 T_cw;
    std::vector<map::PointId> points;
    std::vector<bool> outlier;
    PointCounterUpdates counters;
  };
  std::optional<Found> first;
  PoseAgreement agreement(agreeing_candidates, config_.relocalization_max_step_m,
                          config_.relocalization_max_step_deg);
  for (map::KeyframeId kid : candidates) {
    std::optional<LocalMapSnapshot::Keyframe> kf;
    {
      const map::MapReader view = map_.reader(&lock_clock_);
      kf = snapshot_.add_keyframe(view, kid);
    }
    if (!kf || kf->bad) continue;
    ++reloc_stats_.candidates_tried;
    frame.reset_matches();
    if (match_keyframe(*kf, frame, 0.75f) < 15) continue;
    std::vector<cv::Point3f> object;
    std::vector<cv::Point2f> image;
    std::vector<std::size_t> feature_of;
    for (std::size_t i = 0; i < frame.points.size(); ++i) {
      if (frame.points[i] == map::kNoPoint) continue;
      const LocalMapSnapshot::Point* p = snapshot_.live_point(frame.points[i]);
      if (p == nullptr) continue;
      object.emplace_back(static_cast<float>(p->position.x()), static_cast<float>(p->position.y()),
                          static_cast<float>(p->position.z()));
      image.push_back(frame.features.keypoints[i].pt);
      feature_of.push_back(i);
    }
    if (object.size() < 15) continue;
    cv::Mat rvec, tvec;
    std::vector<int> inliers;
    cv::setRNGSeed(static_cast<int>(frame.index));  // deterministic RANSAC
    const bool found = cv::solvePnPRansac(object, image, camera_.K(), cv::Mat(), rvec, tvec, false, 200, 4.0f,
                                          0.99, inliers, cv::SOLVEPNP_EPNP);
    if (!found || inliers.size() < 10) continue;
    cv::Mat R;
    cv::Rodrigues(rvec, R);
    Eigen::Matrix3d Re;
    Eigen::Vector3d te;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) Re(r, c) = R.at<double>(r, c);
      te(r) = tvec.at<double>(r);
    }
    frame.T_cw = geo::SE3(Eigen::Quaterniond(Re).normalized(), te);
    frame.has_pose = true;
    if (config_.reloc_pnp_inliers_only) {
      // Only RANSAC's inliers enter the first solve (as ORB-SLAM): from a pose fitted to a minority of
      // the matches, the others' pull drags it off and the solve rejects nearly every match.
      std::vector<bool> inlier(object.size(), false);
      for (int k : inliers) inlier[static_cast<std::size_t>(k)] = true;
      for (std::size_t k = 0; k < object.size(); ++k)
        if (!inlier[k]) frame.points[feature_of[k]] = map::kNoPoint;
    }
    if (optimize_pose(frame) < 10) continue;
    // Recover more matches by projection before accepting.
    {
      const map::MapReader view = map_.reader(&lock_clock_);
      update_local_map(view, frame);
    }
    collect_local_points(frame);
    {
      const map::MapReader view = map_.reader(&lock_clock_);
      snapshot_.copy_points(view, local_points_);
    }
    snapshot_.index_copies();
    match_local_points(snapshot_, frame, local_points_, 2.0 * config_.local_search_factor,
                       MatchContext{camera_, pyramid_, depth_.bf}, counters);
    if (optimize_pose(frame) < min_inliers) continue;
    if (spdlog::should_log(spdlog::level::debug)) {
      // Each candidate's camera centre, to set beside the ground truth when views repeat.
      const Eigen::Vector3d c = frame.T_cw.inverse().translation();
      spdlog::debug("frame {}: keyframe {} locates the camera centre at ({:.4f}, {:.4f}, {:.4f}), {} inliers",
                    frame.index, kid, c.x(), c.y(), c.z(), frame.matched());
    }
    if (!first) first = Found{kid, frame.T_cw, frame.points, frame.outlier, counters};
    const PoseAgreement::Verdict verdict = agreement.add(frame.T_cw);
    if (verdict == PoseAgreement::Verdict::Ambiguous) {
      ++reloc_stats_.ambiguous;
      spdlog::debug("frame {}: keyframes {} and {} locate it {:.1f} cm / {:.1f} deg apart: ambiguous",
                    frame.index, first->keyframe, kid, 100.0 * agreement.conflict().translation_m,
                    agreement.conflict().rotation_deg);
      break;
    }
    if (verdict == PoseAgreement::Verdict::Agreed) break;
  }
  if (first && agreement.finish() == PoseAgreement::Verdict::Agreed) {
    frame.T_cw = first->T_cw;
    frame.points = std::move(first->points);
    frame.outlier = std::move(first->outlier);
    counters = std::move(first->counters);
    frame.has_pose = true;
    return first->keyframe;
  }
  frame.has_pose = false;
  return map::kNoKeyframe;
}

bool Tracker::lost_young(const Frame& frame) const {
  // The loss began the frame after the last trusted one.
  return map_started_frame_ && frame.index - lost_streak_ <
                                   *map_started_frame_ + static_cast<std::size_t>(config_.young_map_frames);
}

bool Tracker::new_map_due(const Frame& frame) const {
  if (config_.new_map_after_lost_frames <= 0 || !trusted_motion_.has_pose() || verify_left_ > 0) return false;
  // A map lost young does not wait.
  const bool young = lost_young(frame);
  if (!young && lost_streak_ < static_cast<std::size_t>(config_.new_map_after_lost_frames)) return false;
  const auto with_depth =
      std::count_if(frame.features.depth.begin(), frame.features.depth.end(), [](float d) { return d > 0; });
  return with_depth >= config_.init_min_features;
}

void Tracker::start_new_map(Frame& frame, TrackOutcome& out) {
  {
    map::MapView view = map_.view(&lock_clock_);
    counters_.apply(view);  // what the failed relocalisation saw, as on any lost frame
    // Seeded where the camera is believed to be in the old map's frame: the last trusted pose, carried on
    // by the motion of the frames before it when new_map_seed_motion_frames is set (a camera hidden
    // behind a person keeps moving). A map that merges later is moved where it belongs; one that never
    // merges keeps this seed's error in every frame.
    frame.reset_matches();
    frame.T_cw = *trusted_motion_.extrapolate(frame.index);  // new_map_due(): a trusted pose exists
    frame.has_pose = true;
    current_map_ = map::MapId{next_map_++};
    map_started_frame_ = frame.index;
    open_maps_.push_back(current_map_);
    ++atlas_stats_.maps_created;
    KeyframeDraft draft = draft_keyframe(frame);
    reference_ = create_keyframe(view, frame, std::move(draft), config_.init_all_depth_points);
    spdlog::warn(
        "tracking lost for {} frames: frame {} starts map {} ({} keyframes in all maps) at the last "
        "trusted pose{}",
        lost_streak_, frame.index, map::to_int(current_map_), view.live_keyframes(),
        config_.new_map_seed_motion_frames >= 2 ? ", carried on by its motion" : "");
    state_ = TrackingState::Ok;
    velocity_.reset();
    pending_merge_.reset();
    out.new_keyframe = reference_;
    record_pose(frame, frame.T_cw, out);
  }
  refiner_.reset();  // the anchors belong to the map left behind
  refiner_.set_anchor(out.new_keyframe, frame);
}

bool Tracker::merge_search_due(std::size_t frame_index) {
  if (pending_merge_) return true;
  if (last_merge_search_frame_ &&
      frame_index < *last_merge_search_frame_ + static_cast<std::size_t>(config_.merge_search_interval))
    return false;
  last_merge_search_frame_ = frame_index;
  ++atlas_stats_.merge_searches;
  return true;
}

void Tracker::look_for_other_maps(Frame& frame) {
  // Rare (only while several maps are open). As relocalisation: candidates under a short read, the
  // search on copies, and a view only to merge.
  std::vector<map::KeyframeId> candidates;
  {
    const map::MapReader view = map_.reader(&lock_clock_);
    auto other_map = [&](map::KeyframeId k) {
      const map::Keyframe* kf = view.keyframe(k);
      return kf != nullptr && !kf->bad && kf->map_id != current_map_;
    };
    if (pending_merge_) {
      // Verifying: the keyframe that gave the pose and its neighbours.
      candidates.push_back(pending_merge_->match);
      for (map::KeyframeId k : view.best_covisibles(pending_merge_->match, 5)) candidates.push_back(k);
    } else {
      // The BoW database's candidates in other maps, then (without one) each other map's newest keyframes.
      if (other_map_candidates_) {
        candidates = other_map_candidates_(view, frame, current_map_);
      } else if (reloc_candidates_) {
        for (map::KeyframeId k : reloc_candidates_(view, frame))
          if (other_map(k)) candidates.push_back(k);
      } else {
        const std::vector<map::KeyframeId> ids = view.keyframe_ids_sorted();
        for (auto it = ids.rbegin();
             it != ids.rend() && candidates.size() < config_.relocalization_candidates; ++it)
          if (other_map(*it)) candidates.push_back(*it);
      }
    }
    std::erase_if(candidates, [&](map::KeyframeId k) { return !other_map(k); });
  }
  if (candidates.empty()) {
    if (pending_merge_) ++atlas_stats_.merges_rejected;
    pending_merge_.reset();
    return;
  }
  // The search works on a copy of the frame and must leave the frame's local map as it was.
  Frame probe = frame;
  probe.reset_matches();
  probe.has_pose = false;
  const map::KeyframeId reference = reference_;
  const std::vector<map::KeyframeId> local_keyframes = local_keyframes_;
  const std::vector<map::PointId> local_points = local_points_, local_slots = local_slots_;
  const bool slots_fresh = local_slots_fresh_;
  refined_.assign(probe.features.size(), false);
  PointCounterUpdates ignored;  // the other map's points were not seen by a tracked frame of theirs
  const map::KeyframeId match =
      locate(probe, candidates, ignored, config_.merge_agreeing_candidates, config_.merge_min_inliers);
  reference_ = reference;
  local_keyframes_ = local_keyframes;
  local_points_ = local_points;
  local_slots_ = local_slots;
  local_slots_fresh_ = slots_fresh;
  if (match == map::kNoKeyframe) {
    if (pending_merge_ && frame.index == pending_merge_->last_frame + 1 &&
        pending_merge_->misses < config_.merge_verify_misses) {
      ++pending_merge_->misses;
      pending_merge_->last_frame = frame.index;  // the next frame still continues the check
      spdlog::debug("map merge check at frame {}: map {} not found ({} of {} misses)", frame.index,
                    map::to_int(pending_merge_->other), pending_merge_->misses, config_.merge_verify_misses);
      return;
    }
    if (pending_merge_) {
      ++atlas_stats_.merges_rejected;
      spdlog::info("map merge candidate rejected: frame {} not found in map {} again", frame.index,
                   map::to_int(pending_merge_->other));
    }
    pending_merge_.reset();
    return;
  }
  map::MapView view = map_.view(&lock_clock_);
  const map::Keyframe* matched = view.keyframe(match);
  if (matched == nullptr || matched->bad || matched->map_id == current_map_) {
    pending_merge_.reset();  // culled, or merged by now: nothing to verify against
    return;
  }
  const map::MapId other = matched->map_id;
  const geo::SE3 S_other_cur = probe.T_cw.inverse() * frame.T_cw;             // p_other = S * p_current
  const int inliers_there = probe.matched(), inliers_here = frame.matched();  // for the log lines below
  if (!pending_merge_) {
    ++atlas_stats_.merge_candidates;
    spdlog::info(
        "frame {} (map {}) also located in map {} against keyframe {} ({} inliers there, {} here): "
        "verifying a merge",
        frame.index, map::to_int(current_map_), map::to_int(other), match, inliers_there, inliers_here);
    pending_merge_ = PendingMerge{other, match, S_other_cur, config_.merge_verify_frames, frame.index};
  } else {
    // The same rule as a relocalisation's check: the pose in the other map must be where this frame's
    // pose, moved by the candidate transform, puts it.
    const PoseDeviation d = pose_deviation(probe.T_cw, frame.T_cw * pending_merge_->S_other_cur.inverse());
    if (other != pending_merge_->other || frame.index != pending_merge_->last_frame + 1 ||
        d.translation_m > config_.relocalization_max_step_m ||
        d.rotation_deg > config_.relocalization_max_step_deg) {
      ++atlas_stats_.merges_rejected;
      spdlog::info(
          "map merge candidate rejected at frame {}: {:.1f} cm / {:.2f} deg from the first estimate ({} "
          "inliers there, {} here)",
          frame.index, d.translation_m * 100, d.rotation_deg, inliers_there, inliers_here);
      pending_merge_.reset();
      return;
    }
    spdlog::debug(
        "map merge check at frame {}: {:.1f} cm / {:.2f} deg from the first estimate ({} inliers there, {} "
        "here)",
        frame.index, d.translation_m * 100, d.rotation_deg, inliers_there, inliers_here);
    --pending_merge_->left;
    pending_merge_->last_frame = frame.index;
  }
  if (pending_merge_->left > 0) return;
  pending_merge_.reset();
  // The latest frame's estimate (its pose in both maps is the freshest).
  const map::MapId into = std::min(other, current_map_), from = std::max(other, current_map_);
  const geo::SE3 S_into_from = into == other ? S_other_cur : S_other_cur.inverse();
  // Link keyframes: the frame's reference (current map) and the keyframe it was found against.
  const map::KeyframeId link_from = from == current_map_ ? reference_ : match;
  const map::KeyframeId link_into = from == current_map_ ? match : reference_;
  const std::size_t moved = view.merge_map(from, into, S_into_from, link_from, link_into);
  // Duplicates: a feature matched in both maps sees one point twice; the older map's point stays.
  int fused = 0;
  for (std::size_t i = 0; i < frame.points.size() && i < probe.points.size(); ++i) {
    if (frame.points[i] == map::kNoPoint || frame.outlier[i] || probe.points[i] == map::kNoPoint ||
        probe.outlier[i])
      continue;
    const map::MapPoint* mine = view.live_point(frame.points[i]);
    const map::MapPoint* theirs = view.live_point(probe.points[i]);
    if (mine == nullptr || theirs == nullptr || mine->id == theirs->id) continue;
    const map::PointId keep = from == current_map_ ? theirs->id : mine->id;
    const map::PointId drop = from == current_map_ ? mine->id : theirs->id;
    view.replace_point(drop, keep);
    frame.points[i] = keep;
    ++fused;
  }
  // Then the cheap part of the loop closer's fusion: the older side's local points projected into the
  // newer side's keyframes around the link, so covisibility (and local mapping) joins the two parts.
  std::vector<map::KeyframeId> side = view.best_covisibles(link_from, 10);
  side.push_back(link_from);
  std::vector<map::KeyframeId> other_side = view.best_covisibles(link_into, 10);
  other_side.push_back(link_into);
  std::vector<map::PointId> points;
  std::unordered_set<map::PointId> seen;
  for (map::KeyframeId k : other_side) {
    for (map::PointId pid : view.keyframe(k)->points)
      if (pid != map::kNoPoint && seen.insert(pid).second) points.push_back(pid);
  }
  const MatchContext ctx{camera_, pyramid_, depth_.bf};
  for (map::KeyframeId k : side) fused += fuse_into_keyframe(view, k, points, 4.0, ctx);
  for (map::KeyframeId k : side) view.update_connections(k);
  for (map::KeyframeId k : other_side) view.update_connections(k);
  if (from == current_map_) trusted_motion_.move_frame(S_into_from);
  if (from == current_map_) frame.T_cw = frame.T_cw * S_into_from.inverse();
  std::erase(open_maps_, from);
  if (into != current_map_) map_started_frame_.reset();
  current_map_ = into;
  ++atlas_stats_.merges;
  map_.notify_big_change();  // BA results computed before the move are dropped; the tracker re-reads
  spdlog::info("map {} merged into map {} at frame {}: {} keyframes moved, {} points fused, {} maps open",
               map::to_int(from), map::to_int(into), frame.index, moved, fused, open_maps_.size());
}

}  // namespace sp::track
