#pragma once
// Frame-to-map tracking: constant-velocity prediction, reference-keyframe fallback, relocalisation,
// local-map tracking and the keyframe decision. Runs in the tracking thread. Matching, pose
// optimisation, the sub-pixel refiner and the pose guard work on a LocalMapSnapshot copied under
// short MapReaders; counters and keyframes are written back under one MapView at the end of the
// frame. Relocalisation (rare) searches under one view.
#include <deque>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "stillpoint/common/id_index.hpp"
#include "stillpoint/map/map.hpp"
#include "stillpoint/optimize/pose_optimizer.hpp"
#include "stillpoint/tracking/anchor_refiner.hpp"
#include "stillpoint/tracking/frame.hpp"
#include "stillpoint/tracking/keyframe_policy.hpp"
#include "stillpoint/tracking/local_map_snapshot.hpp"
#include "stillpoint/tracking/new_point_motion_check.hpp"
#include "stillpoint/tracking/pose_guard.hpp"
#include "stillpoint/tracking/trajectory_recorder.hpp"
#include "stillpoint/tracking/trusted_motion.hpp"

namespace sp::track {

struct TrackerConfig {
  int init_min_features = 200;  // features with valid depth needed to start the map
  // px at level 0, constant-velocity projection search. ORB-SLAM uses 15 for RGB-D (7 is its stereo
  // value); 15 lowered ATE on a rotating-camera room (0.53 -> 0.47 cm) and is neutral elsewhere.
  double motion_search_radius = 15.0;
  int min_motion_matches = 20;       // below: fall back to the reference keyframe
  double local_search_factor = 3.0;  // ORB-SLAM's RGB-D window factor for local-map search
  int min_inliers = 30;              // local-map inliers for a frame to count as tracked
  int min_inliers_after_reloc = 50;  // ... for one second after relocalisation
  std::size_t max_local_keyframes = 80;
  int new_points_min = 100;  // close-depth points created per keyframe at least
  // The first keyframe makes a point of every feature with depth, far ones too (ORB-SLAM3's RGB-D
  // initialisation); false = the keyframe rule (close ones, at least new_points_min).
  bool init_all_depth_points = true;
  // Every keyframe makes a point of each unmatched feature with depth (false: close ones first, far
  // ones only up to new_points_min).
  bool keyframe_all_depth_points = false;
  std::size_t relocalization_candidates = 20;
  // A candidate keyframe's PnP RANSAC pose is refined from its inliers only, as ORB-SLAM does (false:
  // every BoW match enters the first solve; outliers, often half the matches, drag the pose off).
  bool reloc_pnp_inliers_only = true;
  // A pose found is accepted only once this many further candidate keyframes that also locate the
  // frame put it within the relocalisation step limits of it (fewer are enough when the candidates run
  // out); one that puts it elsewhere makes the frame ambiguous and it stays lost. 0: the first pose
  // found is taken.
  int reloc_agreeing_candidates = 2;
  // The same for a merge's candidate (its transform is verified over merge_verify_frames anyway).
  int merge_agreeing_candidates = 2;
  // A relocalised pose is trusted (written, allowed to make keyframes) only once this many following
  // frames tracked from it: each with min_inliers_after_reloc local-map inliers and a pose within the
  // step limits of the constant-velocity prediction (zero motion for the first). 0: trusted at once.
  int relocalization_verify_frames = 3;
  double relocalization_max_step_m = 0.05;   // m, camera-centre deviation allowed while verifying
  double relocalization_max_step_deg = 5.0;  // deg, rotation deviation allowed while verifying
  // A tracked pose this far from the constant-velocity prediction is a jump, not a motion: the step is
  // not the next frame's velocity (that frame is found from the reference keyframe, as after a
  // relocalisation). Without it a frame after a jump was predicted a whole jump further on.
  double motion_break_m = 0.05;
  double motion_break_deg = 5.0;
  // Atlas (docs/robustness.md "New maps and merging"): after this many consecutive frames without a
  // trusted pose, a lost frame that fails to relocalise and has init_min_features depth features starts
  // a new map, seeded at the last trusted pose; while more than one map is open, tracked frames look for
  // the other maps' keyframes and merge the newer map into the older one once the pose is verified
  // (merge_verify_frames further frames, the relocalisation limits). 0: never (lost stays lost).
  int new_map_after_lost_frames = 15;
  // A map this tracker started fewer than this many frames ago is young: when it is lost, the first
  // frame that fails to relocalise starts a new map instead of waiting new_map_after_lost_frames (a map
  // lost within a second of its start was begun in a view it cannot hold; ORB-SLAM3 drops a lost map
  // of < 10 keyframes). 0: never (every map waits).
  int young_map_frames = 30;
  // A young map (above) that tracking leaves by relocalising into another map, never merged, is taken
  // back: its frames leave the trajectory and count as lost. A map begun in a view it could not hold
  // (a close object filling it) gave those poses from that object (ORB-SLAM3 drops such a map whole).
  bool drop_abandoned_young_maps = true;
  // While several maps are open, a trusted frame looks for the other maps only every this many frames
  // (the search holds the map lock ~10-50 ms); a candidate found is then verified on every frame. 1: always.
  int merge_search_interval = 5;
  // A merge candidate is carried out once this many next frames found the other map again where the
  // candidate transform puts them (within the relocalisation step limits). 0: at once.
  int merge_verify_frames = 3;
  // ... of which this many may find nothing in the other map without rejecting the candidate: a frame
  // that finds no pose there says nothing against the transform, only one found elsewhere does.
  int merge_verify_misses = 3;
  // A merge search's pose in the other map needs this many local-map inliers (relocalisation needs
  // min_inliers_after_reloc): the frame is tracked in its own map meanwhile, and the agreement of
  // merge_agreeing_candidates and merge_verify_frames checks guard the transform.
  int merge_min_inliers = 50;
  // A new map is seeded at the last trusted pose carried on by the mean motion of the last this many
  // trusted frames (TrustedMotion), for at most new_map_seed_max_frames lost frames. 0 or 1: at the
  // last trusted pose itself.
  int new_map_seed_motion_frames = 0;
  int new_map_seed_max_frames = 30;
  // The features of people proven still that the last this many keyframes were made without
  // (Frame::reserve) are kept; when a frame cannot be tracked without the people (still_people_retry),
  // they are added to their keyframes and made map points from depth (docs/dynamic.md, "A last resort
  // is never mapped"). 0 = none kept [0, 100].
  int still_people_reserve_keyframes = 5;
  // ... only those kept within this many frames before the release: a person still now may have
  // stood elsewhere before [1, 100000].
  int still_people_reserve_max_age_frames = 90;
  // A frame that loses tracking without the people proven still it culled is tracked again with them
  // (their reserve features added to the frame, recent keyframes' reserves mapped first): the tracker,
  // not a keypoint count, decides that the rest is too poor.
  bool still_people_retry = true;
  opt::PoseOptimizerConfig pose;
  KeyframePolicyConfig keyframes;
  PoseGuardConfig guard;
  AnchorRefinerConfig subpixel;
  NewPointMotionCheckConfig new_point_motion;  // a keyframe's new points must have moved as static points
  static TrackerConfig from_yaml(const ConfigReader& r);
};

enum class TrackingState { NotInitialized, Ok, Lost };
const char* to_string(TrackingState s);

struct MappingStatus {
  bool idle = true;
  std::size_t queue = 0;
};

struct TrackOutcome {
  TrackingState state = TrackingState::NotInitialized;
  map::KeyframeId new_keyframe = map::kNoKeyframe;
  int inliers = 0;
  bool relocalized = false;  // this frame relocalised (its pose is still being verified when verifying)
  // The frame tracked from a relocalised pose that is not yet verified: reported Lost, and written to
  // the trajectory only when the verification passes.
  bool verifying = false;
};

// Global relocalisation, counted per frame.
struct RelocalizationStats {
  std::size_t attempts = 0;                 // lost frames on which relocalisation was tried
  std::size_t candidates_tried = 0;         // keyframes matched against over all attempts
  std::size_t poses_found = 0;              // poses with enough inliers after projection refinement
  std::size_t accepted = 0;                 // ... that passed the consistency check over the next frames
  std::size_t rejected_by_consistency = 0;  // ... that did not (back to lost)
  std::size_t ambiguous = 0;                // frames two candidate keyframes put in different places
};

// New maps started after long losses and merges of maps (the Atlas), counted per run.
struct AtlasStats {
  std::size_t maps_created = 0;        // the first map included (0 when a loaded map is the first)
  std::size_t merge_searches = 0;      // frames that searched the other maps for a new candidate
  std::size_t merge_candidates = 0;    // another map's keyframe gave a pose (verification started)
  std::size_t merges = 0;              // ... verified and merged
  std::size_t merges_rejected = 0;     // ... whose next frames did not agree (or were lost)
  std::size_t young_maps_dropped = 0;  // young maps left for another map (drop_abandoned_young_maps)
  std::size_t frames_withdrawn = 0;    // ... their frames, taken out of the trajectory
};

// Relocalisation candidates from anywhere in the map (a BoW keyframe database, a whole-image score),
// best first. Called with the tracker's map view held: it must not take the map lock itself.
using RelocalizationCandidates =
    std::function<std::vector<map::KeyframeId>(const map::MapReader&, const Frame&)>;
// The same query restricted to keyframes of maps other than `current` (map merging), best first.
using OtherMapCandidates =
    std::function<std::vector<map::KeyframeId>(const map::MapReader&, const Frame&, map::MapId current)>;

class Tracker {
 public:
  Tracker(map::Map& map, TrackerConfig config, geo::CameraIntrinsics camera, DepthModel depth,
          map::ScalePyramid pyramid, double fps);

  TrackOutcome track(Frame& frame, const MappingStatus& mapping);
  // How long the last track() held the map lock (and waited for it), all its views together.
  [[nodiscard]] double last_lock_ms() const { return last_lock_.held_ms; }
  [[nodiscard]] const map::LockHoldClock::Times& last_lock() const { return last_lock_; }

  // The map holds a loaded map: frames relocalise in it instead of starting a new map, and count as
  // lost until one does. Call before the first frame.
  void start_in_existing_map();
  // Candidates tried before the recent keyframes when relocalising (unset: recent keyframes only).
  void set_relocalization_candidates(RelocalizationCandidates provider) {
    reloc_candidates_ = std::move(provider);
  }
  // Candidates in other maps for merging (unset: the relocalisation provider's, filtered, else each
  // other map's newest keyframes).
  void set_other_map_candidates(OtherMapCandidates provider) { other_map_candidates_ = std::move(provider); }
  [[nodiscard]] std::optional<std::size_t> first_relocalization_frame() const { return first_reloc_frame_; }

  [[nodiscard]] TrackingState state() const { return state_; }
  [[nodiscard]] std::size_t lost_frames() const { return lost_frames_; }
  // Relocalisations accepted (verified).
  [[nodiscard]] std::size_t relocalizations() const { return relocalizations_; }
  [[nodiscard]] const RelocalizationStats& relocalization_stats() const { return reloc_stats_; }
  [[nodiscard]] const AtlasStats& atlas_stats() const { return atlas_stats_; }
  // The map the tracker works in (after a merge: the map it was merged into).
  [[nodiscard]] map::MapId current_map() const { return current_map_; }
  // Maps holding keyframes that were not merged into another, ascending (map 0 first).
  [[nodiscard]] const std::vector<map::MapId>& open_maps() const { return open_maps_; }
  [[nodiscard]] const PoseGuardStats& guard_stats() const { return guard_stats_; }
  // Tracked frames whose pose broke the constant-velocity motion (TrackerConfig::motion_break_m).
  [[nodiscard]] std::size_t motion_breaks() const { return motion_breaks_; }
  // Keyframe candidates for new points whose flow disagreed with the tracked motion (not made points).
  [[nodiscard]] std::size_t new_points_moving() const { return new_points_moving_; }
  // Still people's reserve features mapped when a frame could not be tracked without them.
  struct ReserveStats {
    std::size_t releases = 0;                  // frames that mapped keyframes' reserve features
    std::size_t points = 0;                    // map points made from them
    std::size_t tracker_releases = 0;          // frames lost without the still people, tried again with them
    std::size_t tracker_releases_tracked = 0;  // ... and tracked then
  };
  [[nodiscard]] const ReserveStats& reserve_stats() const { return reserve_stats_; }
  [[nodiscard]] const AnchorRefinerStats& subpixel_stats() const { return refiner_.stats(); }
  [[nodiscard]] const TrajectoryRecorder& trajectory() const { return trajectory_; }
  [[nodiscard]] const KeyframePolicy& policy() const { return *policy_; }
  // Camera motion from the previous frame to the next one by the constant-velocity model (T_cur_prev).
  [[nodiscard]] std::optional<geo::SE3> predicted_motion() const { return velocity_; }

 private:
  TrackOutcome track_frame(Frame& frame, const MappingStatus& mapping);
  // Writes the tracked frame's pose relative to its reference keyframe (held back while verifying).
  void record_pose(Frame& frame, const geo::SE3& reference_T_cw, TrackOutcome& out);
  bool initialize(map::MapView& view, Frame& frame);
  // The reserve features kept with recent keyframes become map points; returns how many.
  std::size_t map_reserve(const Frame& frame);
  // A frame lost without the people proven still: adds its reserve features (the people) to its
  // features and maps the keyframes' reserves; false when neither adds anything (or the retry is off).
  bool release_reserve(Frame& frame);
  bool track_motion_model(Frame& frame);
  bool track_reference_keyframe(Frame& frame);
  bool relocalize(Frame& frame);
  // Relocalisation's search: the first candidate keyframe that gives the frame a pose with
  // `min_inliers` local-map inliers (frame.T_cw and matches set), once `agreeing_candidates`
  // further ones that give a pose agree with it (PoseAgreement), or kNoKeyframe (none, or ambiguous).
  // Copies what it reads under short reads (a candidate's keyframe, then its local map) and matches and
  // solves on the copies without the lock.
  map::KeyframeId locate(Frame& frame, const std::vector<map::KeyframeId>& candidates,
                         PointCounterUpdates& counters, int agreeing_candidates, int min_inliers);
  // Atlas: a lost frame starts a new map when lost long enough (TrackerConfig::new_map_after_lost_frames).
  [[nodiscard]] bool new_map_due(const Frame& frame) const;
  // The map tracking is in was started by this tracker and lost within young_map_frames of its start.
  [[nodiscard]] bool lost_young(const Frame& frame) const;
  void start_new_map(Frame& frame, TrackOutcome& out);
  // Atlas: a trusted frame of one of several open maps looks for the other maps' keyframes; a pose there
  // verified over the next frames merges the newer map into the older one.
  void look_for_other_maps(Frame& frame);
  // A merge being verified looks on every frame; a new search waits merge_search_interval frames.
  bool merge_search_due(std::size_t frame_index);
  // The tail of track_frame: outcome state, outliers dropped, last frame kept.
  TrackOutcome finish_frame(Frame& frame, TrackOutcome& out);
  // One frame of the check after a relocalisation: true while the frame agrees with the relocalised
  // pose's motion (see TrackerConfig::relocalization_verify_frames).
  [[nodiscard]] bool consistent_after_relocalization(const Frame& frame, const geo::SE3& expected_T_cw) const;
  // The relocalised pose passed its check: counted, and the frames tracked from it are written.
  void accept_relocalization();
  bool track_local_map(Frame& frame);
  // The pose guard (PoseGuardConfig). True when the frame jumped: it must not become a keyframe.
  bool guard_pose(Frame& frame, const geo::SE3& predicted_T_cw);
  int optimize_pose(Frame& frame);
  // Picks the local keyframes around the frame's matches (and the reference) and copies their point
  // slots; collect_local_points() then picks the local points from them without the lock.
  void update_local_map(const map::MapReader& view, Frame& frame);
  void collect_local_points(const Frame& frame);
  void refresh_last_frame(const map::MapReader& view);
  // The reference keyframe's points seen by enough keyframes to count as mapped (the keyframe rules' base).
  [[nodiscard]] int reference_tracked(const map::MapReader& view) const;
  [[nodiscard]] bool need_keyframe(const map::MapReader& view, const Frame& frame,
                                   const MappingStatus& mapping) const;
  // A keyframe is drafted from the frame without the lock (features, grid, thumbnail, features by
  // depth), then stored with its new points under a view; the caller makes it the refiner's anchor
  // after that view (the anchor's image pyramid needs no lock).
  struct KeyframeDraft {
    map::Keyframe keyframe;
    std::vector<std::size_t> by_depth;  // features, closest first
    std::vector<bool> moved;            // per feature: no new point, it moved against the last frame
  };
  // check_motion: new-point candidates are checked against the motion from the last frame
  // (NewPointMotionCheck), outside the lock like the rest of the draft.
  [[nodiscard]] KeyframeDraft draft_keyframe(const Frame& frame, bool check_motion = false) const;
  // all_depth_points: every feature with depth makes a point, not only the close ones.
  map::KeyframeId create_keyframe(map::MapView& view, Frame& frame, KeyframeDraft draft,
                                  bool all_depth_points);
  // Per feature of the frame: true where new_point_check_ finds it moved against the last frame. The
  // candidates are the features with depth and no point in `slots` (the drafted keyframe's).
  [[nodiscard]] std::vector<bool> moved_new_point_candidates(const Frame& frame,
                                                             const std::vector<map::PointId>& slots) const;

  map::Map& map_;
  TrackerConfig config_;
  geo::CameraIntrinsics camera_;
  DepthModel depth_;
  map::ScalePyramid pyramid_;
  double fps_;
  std::unique_ptr<KeyframePolicy> policy_;
  opt::CameraModel camera_model_;

  TrackingState state_ = TrackingState::NotInitialized;
  Frame last_frame_;
  std::optional<geo::SE3> velocity_;  // T_cur_last of the last tracked step
  // This frame's constant-velocity prediction while it is tracked, for the pose solves' motion prior
  // (used or not by optimize_pose); none while lost or right after a jump.
  std::optional<geo::SE3> motion_prior_;
  map::KeyframeId reference_ = map::kNoKeyframe;
  std::size_t last_keyframe_frame_ = 0;
  std::size_t last_reloc_frame_ = 0;
  std::uint64_t big_changes_seen_ = 0;
  std::vector<map::KeyframeId> local_keyframes_;
  std::vector<map::PointId> local_points_;
  std::vector<map::PointId> local_slots_;  // the local keyframes' point slots, in keyframe order
  bool local_slots_fresh_ = false;         // update_local_map() refilled them since the last collect
  BasicIdIndex<map::PointId>
      seen_;  // collect_local_points()' scratch (point id -> unused), kept for its slots
  std::unordered_map<map::KeyframeId, int> keyframe_counts_;  // update_local_map()'s scratch, idem
  std::size_t lost_frames_ = 0;
  std::string why_lost_;  // the failed step and its counts, for the log when tracking is lost
  std::size_t relocalizations_ = 0;
  bool relocalized_once_ = false;            // a relocalised pose was found (last_reloc_frame_ is meaningful)
  std::size_t reloc_frame_ = 0;              // frame of the relocalised pose being verified (or the last one)
  int verify_left_ = 0;                      // frames still to check after a relocalisation (0: trusted)
  std::vector<TrajectoryEntry> unverified_;  // frames tracked since then, written once verified
  RelocalizationStats reloc_stats_;
  RelocalizationCandidates reloc_candidates_;
  OtherMapCandidates other_map_candidates_;
  std::optional<std::size_t> first_reloc_frame_;
  // Atlas state.
  map::MapId current_map_ = map::kFirstMap;
  std::uint32_t next_map_ = 0;                    // the id the next new map gets
  std::vector<map::MapId> open_maps_;             // maps not merged into another
  std::optional<std::size_t> map_started_frame_;  // where this tracker started the current map
  std::size_t lost_streak_ = 0;                   // frames since the last trusted (written) one
  TrustedMotion trusted_motion_;  // the last trusted pose and those before it (a new map's seed)
  struct PendingMerge {
    map::MapId other = map::kFirstMap;
    map::KeyframeId match = map::kNoKeyframe;
    geo::SE3 S_other_cur;  // p_other = S * p_current
    int left = 0;          // frames still to agree
    std::size_t last_frame = 0;
    int misses = 0;  // frames since the candidate that did not find the other map at all
  };
  std::optional<PendingMerge> pending_merge_;
  std::optional<std::size_t> last_merge_search_frame_;
  AtlasStats atlas_stats_;
  TrajectoryRecorder trajectory_;
  PoseGuardRules guard_;
  PoseGuardStats guard_stats_;
  std::size_t motion_breaks_ = 0;
  NewPointMotionCheck new_point_check_;
  std::size_t new_points_moving_ = 0;
  struct Reserve {
    map::KeyframeId keyframe = map::kNoKeyframe;
    std::size_t frame_index = 0;
    map::FeatureSet features;  // the frame's Frame::reserve
  };
  std::deque<Reserve> reserves_;  // oldest first, at most still_people_reserve_keyframes
  ReserveStats reserve_stats_;
  AnchorRefiner refiner_;
  std::vector<bool> refined_;      // per feature of the frame being tracked: position aligned with the anchor
  LocalMapSnapshot snapshot_;      // the map records this frame reads, copied under short readers
  PointCounterUpdates counters_;   // ... and the counters it raises, written back at the end
  map::LockHoldClock lock_clock_;  // every view the tracker takes is timed on it
  map::LockHoldClock::Times last_lock_;
};

}  // namespace sp::track
