#include "stillpoint/tracking/local_map_snapshot.hpp"

#include <algorithm>
#include <cstring>

namespace sp::track {

void LocalMapSnapshot::reset(std::vector<map::KeyframeId> anchors) {
  points_.clear();
  anchor_features_.clear();
  index_.clear();
  poses_.clear();
  unindexed_.clear();
  anchors_ = std::move(anchors);
}

const LocalMapSnapshot::Point* LocalMapSnapshot::add(const map::MapReader& view, map::PointId id) {
  const map::MapPoint* p = view.live_point(id);
  if (p == nullptr) {
    forget(id);  // gone since an earlier copy (another stage culled it between two views)
    return nullptr;
  }
  const auto [slot, inserted] = index_.try_emplace(p->id, points_.size());
  if (inserted) new_slot();
  copy(*p, slot);
  if (id != p->id) index_.insert_or_assign(id, slot);
  return &points_[slot];
}

std::size_t LocalMapSnapshot::new_slot() {
  points_.emplace_back();
  anchor_features_.resize(points_.size() * anchors_.size(), -1);
  return points_.size() - 1;
}

void LocalMapSnapshot::forget(map::PointId id) {
  // The copy found under this id, and the id it was copied as (a replaced point's successor).
  if (const std::size_t* slot = index_.find(id)) {
    index_.erase(points_[*slot].id);
    index_.erase(id);
  }
}

void LocalMapSnapshot::copy(const map::MapPoint& p, std::size_t slot) {
  Point& c = points_[slot];
  c.id = p.id;
  c.position = p.position;
  c.normal = p.normal;
  c.min_distance = p.min_distance;
  c.max_distance = p.max_distance;
  const std::size_t bytes =
      std::min<std::size_t>(c.descriptor.size(), p.descriptor.total() * p.descriptor.elemSize());
  if (bytes > 0) std::memcpy(c.descriptor.data(), p.descriptor.ptr<std::uint8_t>(), bytes);
  for (std::size_t a = 0; a < anchors_.size(); ++a) {
    const auto obs = p.observations.find(anchors_[a]);
    anchor_features_[slot * anchors_.size() + a] = obs == p.observations.end() ? -1 : obs->second;
  }
}

void LocalMapSnapshot::copy_points(const map::MapReader& view, const std::vector<map::PointId>& ids) {
  points_.reserve(points_.size() + ids.size());
  anchor_features_.reserve(anchor_features_.size() + ids.size() * anchors_.size());
  for (map::PointId id : ids) {
    const map::MapPoint* p = view.live_point(id);
    if (p == nullptr) {
      unindexed_.emplace_back(id, kGone);
      continue;
    }
    const std::size_t slot = new_slot();
    copy(*p, slot);
    unindexed_.emplace_back(id, slot);
  }
}

void LocalMapSnapshot::index_copies() {
  for (const auto& [id, slot] : unindexed_) {
    if (slot == kGone) {
      forget(id);
      continue;
    }
    index_.insert_or_assign(points_[slot].id, slot);  // a newer copy of a point copied before replaces it
    index_.insert_or_assign(id, slot);
  }
  unindexed_.clear();
}

const LocalMapSnapshot::Point* LocalMapSnapshot::live_point(map::PointId id) const {
  const std::size_t* slot = index_.find(id);
  return slot == nullptr ? nullptr : &points_[*slot];
}

int LocalMapSnapshot::anchor_feature(const Point& p, map::KeyframeId anchor) const {
  const auto a = std::find(anchors_.begin(), anchors_.end(), anchor);
  if (a == anchors_.end()) return -1;
  const auto slot = static_cast<std::size_t>(&p - points_.data());
  return anchor_features_[slot * anchors_.size() + static_cast<std::size_t>(a - anchors_.begin())];
}

std::optional<LocalMapSnapshot::Keyframe> LocalMapSnapshot::add_keyframe(const map::MapReader& view,
                                                                         map::KeyframeId id) {
  const map::Keyframe* kf = view.keyframe(id);
  if (kf == nullptr) return std::nullopt;
  Keyframe c;
  c.id = id;
  c.bad = kf->bad;
  c.T_cw = kf->T_cw;
  c.descriptors = kf->features.descriptors.clone();
  c.angles.reserve(kf->features.keypoints.size());
  for (const cv::KeyPoint& kp : kf->features.keypoints) c.angles.push_back(kp.angle);
  c.points.assign(kf->points.size(), map::kNoPoint);
  for (std::size_t i = 0; i < kf->points.size(); ++i) {
    if (kf->points[i] == map::kNoPoint) continue;
    if (const Point* p = add(view, kf->points[i])) c.points[i] = p->id;
  }
  return c;
}

void LocalMapSnapshot::add_pose(const map::MapReader& view, map::KeyframeId id) {
  if (const map::Keyframe* kf = view.keyframe(id)) poses_[id] = Pose{kf->T_cw, kf->bad};
}

const LocalMapSnapshot::Pose* LocalMapSnapshot::pose(map::KeyframeId id) const {
  const auto it = poses_.find(id);
  return it == poses_.end() ? nullptr : &it->second;
}

void PointCounterUpdates::apply(map::MapView& view) {
  for (map::PointId id : visible_) {
    if (map::MapPoint* p = view.live_point(id)) ++p->visible;
  }
  for (map::PointId id : found_) {
    if (map::MapPoint* p = view.live_point(id)) ++p->found;
  }
  clear();
}

void PointCounterUpdates::clear() {
  visible_.clear();
  found_.clear();
}

}  // namespace sp::track
