#pragma once
// The map: the one shared mutable structure of the system.
//
// Lock discipline: the Map is a monitor. Every read or write of keyframes and map points goes
// through a MapReader (reads only) or a MapView (reads and writes), which hold the map's single mutex
// for their lifetime. Stages keep views short: heavy work (feature extraction, detection, the numeric
// part of bundle adjustment, the tracker's matching and pose optimisation) runs on copies without the
// lock, and results are written back through a new view. Ids, never pointers, are kept across views;
// a pointer returned by a view is valid only while that view lives.
#include <atomic>
#include <chrono>
#include <mutex>
#include <optional>
#include <unordered_map>
#include <utility>
#include <vector>

#include "stillpoint/map/keyframe.hpp"

namespace sp::map {

class Map;

// Adds up how long the views given it held the map lock and waited for it (wall time): the tracking
// thread's lock time per frame (stats.json stages_ms.track_lock, track_lock_wait). One per thread,
// never shared.
class LockHoldClock {
 public:
  struct Times {
    double held_ms = 0;    // from taking the lock to releasing it
    double waited_ms = 0;  // spent waiting to take it
  };
  void add(const Times& t) {
    times_.held_ms += t.held_ms;
    times_.waited_ms += t.waited_ms;
  }
  // The times added since the last call; they start again from zero.
  Times take() { return std::exchange(times_, Times{}); }

 private:
  Times times_;
};

// Read-only access under the map's lock, for code that only reads.
class MapReader {
 public:
  // With a clock, the time waited for the lock and held is added to it.
  explicit MapReader(Map& map, LockHoldClock* clock = nullptr);
  MapReader(const MapReader&) = delete;
  MapReader& operator=(const MapReader&) = delete;
  ~MapReader();

  [[nodiscard]] const Keyframe* keyframe(KeyframeId id) const;
  [[nodiscard]] const MapPoint* point(PointId id) const;
  // Follows replaced_by links; nullptr when the point is gone or bad.
  [[nodiscard]] const MapPoint* live_point(PointId id) const;

  [[nodiscard]] std::vector<KeyframeId> best_covisibles(KeyframeId kf, std::size_t n) const;
  [[nodiscard]] std::vector<KeyframeId> covisibles_with_weight(KeyframeId kf, int min_weight) const;
  // Points of kf with at least min_observations weighted observations (see weighted_observations).
  [[nodiscard]] int tracked_points(KeyframeId kf, int min_observations) const;
  // Observations of p with one counted twice where the keyframe has depth at the feature: a depth
  // reading is a second view (ORB-SLAM's convention for stereo and RGB-D observations).
  [[nodiscard]] int weighted_observations(const MapPoint& p) const;

  [[nodiscard]] const std::unordered_map<KeyframeId, Keyframe>& keyframes() const;
  [[nodiscard]] const std::unordered_map<PointId, MapPoint>& points() const;
  [[nodiscard]] std::vector<KeyframeId> keyframe_ids_sorted() const;
  [[nodiscard]] std::size_t live_keyframes() const;
  [[nodiscard]] std::size_t live_keyframes(MapId m) const;  // ... of map m
  // The lowest live keyframe id of map m, its gauge root in BA and the pose graph (kNoKeyframe: none).
  [[nodiscard]] KeyframeId map_root(MapId m) const;
  // The maps that hold live keyframes, ascending.
  [[nodiscard]] std::vector<MapId> live_maps() const;
  [[nodiscard]] std::size_t live_points() const;
  // The ids the next add_keyframe / add_point will hand out (map files save them).
  [[nodiscard]] std::pair<KeyframeId, PointId> next_ids() const;

 protected:
  Map& map_;

 private:
  // Declared before lock_: set before the lock is taken.
  LockHoldClock* clock_ = nullptr;
  std::chrono::steady_clock::time_point asked_at_;
  std::unique_lock<std::mutex> lock_;
  std::chrono::steady_clock::time_point locked_at_;
};

// Reads and writes under the map's lock.
class MapView : public MapReader {
 public:
  explicit MapView(Map& map, LockHoldClock* clock = nullptr) : MapReader(map, clock) {}

  using MapReader::keyframe;
  using MapReader::live_point;
  using MapReader::point;
  [[nodiscard]] Keyframe* keyframe(KeyframeId id);
  [[nodiscard]] MapPoint* point(PointId id);
  [[nodiscard]] MapPoint* live_point(PointId id);

  KeyframeId add_keyframe(Keyframe kf);  // assigns the id; observations of kf.points are added
  PointId add_point(MapPoint p);         // assigns the id

  // Appends features to a live keyframe (features seen when it was made, mapped later); their point
  // slots start empty and the keyframe's grid is rebuilt over an image_size image. Returns the index of
  // the first appended feature, or nothing when the keyframe is missing or culled. Features already
  // there keep their indices, so observations and copies other stages hold stay valid.
  std::optional<std::size_t> append_features(KeyframeId kf, const FeatureSet& extra, cv::Size image_size);
  void add_observation(PointId p, KeyframeId kf, int feature);
  void erase_observation(PointId p, KeyframeId kf);
  void erase_point(PointId p);  // marks bad and detaches from keyframes
  // Marks bad, detaches, re-parents the spanning tree. Refused (false) for the root keyframe, a held
  // keyframe (hold_keyframe) and one already culled.
  bool erase_keyframe(KeyframeId kf);
  // Holds a live keyframe against culling (counted, so holds nest); false when it is missing or culled.
  // A stage that verifies in one view and writes in a later one holds the keyframes it relies on, so
  // local mapping cannot cull them in between. Prefer map::KeyframeHold, which releases for you.
  bool hold_keyframe(KeyframeId kf);
  void release_keyframe(KeyframeId kf);
  void replace_point(PointId old_id, PointId by);
  // Map merging: moves every keyframe (culled ones too) and point of map `from` into the frame of map
  // `into` (p_into = S_into_from * p_from), relabels the keyframes to `into`, hangs `from`'s root
  // keyframe under `link_into` in the spanning tree and records a loop edge link_from <-> link_into
  // (the pose graph's edge between the two parts). Returns the keyframes moved.
  std::size_t merge_map(MapId from, MapId into, const geo::SE3& S_into_from, KeyframeId link_from,
                        KeyframeId link_into);

  void update_point_descriptor(PointId p);
  void update_point_normal_and_depth(PointId p, const ScalePyramid& pyramid);
  // Recomputes kf's covisibility edges (and its neighbours' back edges) and its spanning-tree parent.
  void update_connections(KeyframeId kf, int min_weight = 15);

  // Frees what bad records hold once they went bad before keyframe id `retired_before`: map points
  // are dropped (ids still held elsewhere then resolve to nullptr, as for any erased point) and culled
  // keyframes shrink to their pose and spanning-tree link, which the trajectory still follows.
  // Records are kept a while first so that ids other stages hold across views still resolve (and
  // replaced points still redirect). Without this a long run grows by every culled record.
  // Returns the number of records purged or slimmed.
  std::size_t purge_bad(KeyframeId retired_before);
  // Fills an EMPTY map with records that keep their ids (a loaded map file); new ids continue from
  // the given counters. Records are stored as they are: the map-file loader has validated their
  // cross-references. Throws sp::Error when the map is not empty or an id is 0, repeated or >= its counter.
  void restore(std::vector<Keyframe> keyframes, std::vector<MapPoint> points, KeyframeId next_keyframe_id,
               PointId next_point_id);
};

class Map {
 public:
  Map() = default;
  Map(const Map&) = delete;
  Map& operator=(const Map&) = delete;

  [[nodiscard]] MapView view(LockHoldClock* clock = nullptr) { return MapView(*this, clock); }
  [[nodiscard]] MapReader reader(LockHoldClock* clock = nullptr) { return MapReader(*this, clock); }
  // Incremented after a loop correction so the tracker refreshes its motion model and last frame.
  [[nodiscard]] std::uint64_t big_change_count() const { return big_changes_.load(); }
  void notify_big_change() { ++big_changes_; }

 private:
  friend class MapReader;
  friend class MapView;
  std::mutex mutex_;
  std::unordered_map<KeyframeId, Keyframe> keyframes_;
  std::unordered_map<PointId, MapPoint> points_;
  KeyframeId next_keyframe_id_{1};
  PointId next_point_id_{1};
  std::atomic<std::uint64_t> big_changes_{0};
};

}  // namespace sp::map
