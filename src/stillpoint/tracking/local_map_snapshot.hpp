#pragma once
// What one frame's tracking reads from the map, copied under a short MapReader so that matching, pose
// optimisation, the sub-pixel refiner and the pose guard run without the map lock; and the counter
// updates they produce, written back under the next MapView (docs/ARCHITECTURE.md, "The map and its
// lock discipline"). A copy answers for a point id as MapReader::live_point did when it was taken.
#include <array>
#include <cstdint>
#include <opencv2/core.hpp>
#include <optional>
#include <unordered_map>
#include <vector>

#include "stillpoint/common/id_index.hpp"
#include "stillpoint/features/descriptor.hpp"
#include "stillpoint/geometry/lie.hpp"
#include "stillpoint/map/map.hpp"

namespace sp::track {

class LocalMapSnapshot {
 public:
  struct Point {
    map::PointId id = map::kNoPoint;  // the live id
    Eigen::Vector3d position = Eigen::Vector3d::Zero();
    Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
    double min_distance = 0, max_distance = 0;
    std::array<std::uint8_t, feat::kDescriptorBytes> descriptor{};
    [[nodiscard]] int predict_level(double distance, const map::ScalePyramid& pyramid) const {
      return map::predict_level(max_distance, distance, pyramid);
    }
  };
  // A keyframe for descriptor matching (reference keyframe, relocalisation candidates).
  struct Keyframe {
    map::KeyframeId id = map::kNoKeyframe;
    bool bad = false;
    geo::SE3 T_cw;
    cv::Mat descriptors;               // own copy, N x 32
    std::vector<float> angles;         // per feature, keypoint orientation
    std::vector<map::PointId> points;  // per feature: the live point's id, kNoPoint when none
  };
  struct Pose {
    geo::SE3 T_cw;
    bool bad = false;
  };

  // Forgets every copy. Points keep their observation in each of `anchors` (the refiner's keyframes).
  void reset(std::vector<map::KeyframeId> anchors);

  // Copies the live point behind `id` (following replacements); found afterwards under `id` and under
  // its live id. A copy already there is refreshed; one whose point has gone since is forgotten.
  const Point* add(const map::MapReader& view, map::PointId id);
  // Copies many points under one read as add() does, but leaves the hashing for index_copies(), to be
  // called after the read ends: until then the copies are not found.
  void copy_points(const map::MapReader& view, const std::vector<map::PointId>& ids);
  void index_copies();
  // The copy for an id given to add() or a live id it resolved to; nullptr when none.
  [[nodiscard]] const Point* live_point(map::PointId id) const;
  // The feature observing the point in `anchor`, -1 when none (or the anchor was not given to reset()).
  [[nodiscard]] int anchor_feature(const Point& p, map::KeyframeId anchor) const;

  // Copies a keyframe (culled ones too, flagged bad) and adds its live points; nullopt when missing.
  std::optional<Keyframe> add_keyframe(const map::MapReader& view, map::KeyframeId id);

  // Copies a keyframe's pose (and whether it is culled) when it exists.
  void add_pose(const map::MapReader& view, map::KeyframeId id);
  [[nodiscard]] const Pose* pose(map::KeyframeId id) const;

  [[nodiscard]] std::size_t size() const { return points_.size(); }

 private:
  std::size_t new_slot();        // an empty copy appended, with its anchor-feature row
  void forget(map::PointId id);  // drops the copy found under id from the index
  void copy(const map::MapPoint& p, std::size_t slot);

  std::vector<Point> points_;
  std::vector<int> anchor_features_;  // points_.size() x anchors_.size(), row per point
  BasicIdIndex<map::PointId>
      index_;  // id (asked or live) -> slot in points_; rebuilt every frame, allocation-free
  static constexpr std::size_t kGone = static_cast<std::size_t>(-1);
  std::vector<std::pair<map::PointId, std::size_t>> unindexed_;  // copy_points(): (id asked, slot or kGone)
  std::vector<map::KeyframeId> anchors_;
  std::unordered_map<map::KeyframeId, Pose> poses_;
};

// The visible / found counters a frame tracked on a snapshot raises, applied under a later MapView to
// the points still alive then (following replacements; points gone meanwhile are skipped).
class PointCounterUpdates {
 public:
  void visible(map::PointId id) { visible_.push_back(id); }
  void found(map::PointId id) { found_.push_back(id); }
  void apply(map::MapView& view);
  void clear();
  [[nodiscard]] bool empty() const { return visible_.empty() && found_.empty(); }

 private:
  std::vector<map::PointId> visible_, found_;
};

}  // namespace sp::track
