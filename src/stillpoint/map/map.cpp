#include "stillpoint/map/map.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "stillpoint/common/error.hpp"
#include "stillpoint/features/descriptor.hpp"

namespace sp::map {

namespace {

// MapReader::weighted_observations, stopping once it reaches `enough`.
int weighted_observations_upto(const std::unordered_map<KeyframeId, Keyframe>& keyframes, const MapPoint& p,
                               int enough) {
  int n = 0;
  for (const auto& [kid, feature] : p.observations) {
    if (n >= enough) break;
    const auto kit = keyframes.find(kid);
    if (kit == keyframes.end()) continue;
    const auto& u_right = kit->second.features.u_right;
    const auto f = static_cast<std::size_t>(feature);
    n += f < u_right.size() && u_right[f] >= 0 ? 2 : 1;
  }
  return n;
}

}  // namespace

int MapPoint::predict_level(double distance, const ScalePyramid& pyramid) const {
  return map::predict_level(max_distance, distance, pyramid);
}

int predict_level(double max_distance, double distance, const ScalePyramid& pyramid) {
  if (distance <= 0 || max_distance <= 0) return 0;
  const double ratio = max_distance / distance;
  const int level = static_cast<int>(std::ceil(std::log(ratio) / std::log(pyramid.scale_factor)));
  return std::clamp(level, 0, pyramid.levels - 1);
}

namespace {

double ms_since(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t).count();
}

}  // namespace

MapReader::MapReader(Map& map, LockHoldClock* clock)
    : map_(map),
      clock_(clock),
      asked_at_(clock != nullptr ? std::chrono::steady_clock::now()
                                 : std::chrono::steady_clock::time_point{}),
      lock_(map.mutex_) {
  // steady_clock only (no system call) while the lock is held: the timing must not invite preemption.
  if (clock_ != nullptr) locked_at_ = std::chrono::steady_clock::now();
}

MapReader::~MapReader() {
  // Runs before lock_ is released, so the hold measured ends just before the unlock.
  if (clock_ == nullptr) return;
  clock_->add(
      {ms_since(locked_at_), std::chrono::duration<double, std::milli>(locked_at_ - asked_at_).count()});
}

const Keyframe* MapReader::keyframe(KeyframeId id) const {
  auto it = map_.keyframes_.find(id);
  return it == map_.keyframes_.end() ? nullptr : &it->second;
}

const MapPoint* MapReader::point(PointId id) const {
  auto it = map_.points_.find(id);
  return it == map_.points_.end() ? nullptr : &it->second;
}

const MapPoint* MapReader::live_point(PointId id) const {
  for (int hops = 0; hops < 8 && id != kNoPoint; ++hops) {
    const MapPoint* p = point(id);
    if (p == nullptr) return nullptr;
    if (!p->bad) return p;
    id = p->replaced_by;
  }
  return nullptr;
}

// The records are not const (the map owns them mutably); a MapView may hand them out for writing.
Keyframe* MapView::keyframe(KeyframeId id) { return const_cast<Keyframe*>(MapReader::keyframe(id)); }

MapPoint* MapView::point(PointId id) { return const_cast<MapPoint*>(MapReader::point(id)); }

MapPoint* MapView::live_point(PointId id) { return const_cast<MapPoint*>(MapReader::live_point(id)); }

KeyframeId MapView::add_keyframe(Keyframe kf) {
  kf.id = std::exchange(map_.next_keyframe_id_, map_.next_keyframe_id_.next());
  if (kf.points.size() != kf.features.size()) kf.points.assign(kf.features.size(), kNoPoint);
  const KeyframeId id = kf.id;
  auto [it, inserted] = map_.keyframes_.emplace(id, std::move(kf));
  (void)inserted;
  Keyframe& stored = it->second;
  for (std::size_t i = 0; i < stored.points.size(); ++i) {
    if (stored.points[i] == kNoPoint) continue;
    MapPoint* p = live_point(stored.points[i]);
    if (p == nullptr) {
      stored.points[i] = kNoPoint;
      continue;
    }
    stored.points[i] = p->id;
    if (p->observations.contains(id)) {
      stored.points[i] = kNoPoint;  // one feature per point per keyframe
      continue;
    }
    p->observations[id] = static_cast<int>(i);
  }
  return id;
}

PointId MapView::add_point(MapPoint p) {
  p.id = std::exchange(map_.next_point_id_, map_.next_point_id_.next());
  const PointId id = p.id;
  map_.points_.emplace(id, std::move(p));
  return id;
}

std::optional<std::size_t> MapView::append_features(KeyframeId kid, const FeatureSet& extra,
                                                    cv::Size image_size) {
  Keyframe* kf = keyframe(kid);
  if (kf == nullptr || kf->bad) return std::nullopt;
  if (extra.descriptors.rows != static_cast<int>(extra.size()) || extra.depth.size() != extra.size() ||
      extra.u_right.size() != extra.size() || kf->points.size() != kf->features.size())
    throw Error("map: append_features with inconsistent feature arrays");
  const std::size_t first = kf->features.size();
  if (extra.size() == 0) return first;
  append(kf->features, extra);  // new descriptor buffer: copies other stages hold stay as they were
  kf->points.resize(kf->features.size(), kNoPoint);
  kf->index = make_feature_grid(kf->features.keypoints, image_size.width, image_size.height);
  return first;
}

void MapView::add_observation(PointId pid, KeyframeId kid, int feature) {
  MapPoint* p = point(pid);
  Keyframe* kf = keyframe(kid);
  if (p == nullptr || kf == nullptr || feature < 0 ||
      static_cast<std::size_t>(feature) >= kf->points.size()) {
    throw Error("map: add_observation with an unknown point, keyframe or feature");
  }
  if (p->observations.contains(kid)) return;
  p->observations[kid] = feature;
  kf->points[static_cast<std::size_t>(feature)] = pid;
}

void MapView::erase_observation(PointId pid, KeyframeId kid) {
  MapPoint* p = point(pid);
  Keyframe* kf = keyframe(kid);
  if (p == nullptr) return;
  auto it = p->observations.find(kid);
  if (it == p->observations.end()) return;
  if (kf != nullptr && static_cast<std::size_t>(it->second) < kf->points.size() &&
      kf->points[static_cast<std::size_t>(it->second)] == pid) {
    kf->points[static_cast<std::size_t>(it->second)] = kNoPoint;
  }
  p->observations.erase(it);
  if (p->reference == kid && !p->observations.empty()) p->reference = p->observations.begin()->first;
  // RGB-D points are created from one view, so a point needs at least one observation to live.
  if (p->observations.empty()) erase_point(pid);
}

void MapView::erase_point(PointId pid) {
  MapPoint* p = point(pid);
  if (p == nullptr || p->bad) return;
  p->bad = true;
  p->retired_at = map_.next_keyframe_id_;
  for (const auto& [kid, feature] : p->observations) {
    Keyframe* kf = keyframe(kid);
    if (kf != nullptr && static_cast<std::size_t>(feature) < kf->points.size() &&
        kf->points[static_cast<std::size_t>(feature)] == pid) {
      kf->points[static_cast<std::size_t>(feature)] = kNoPoint;
    }
  }
  p->observations.clear();
}

void MapView::replace_point(PointId old_id, PointId by) {
  if (old_id == by) return;
  MapPoint* old_p = point(old_id);
  MapPoint* new_p = point(by);
  if (old_p == nullptr || new_p == nullptr || old_p->bad || new_p->bad) return;
  const auto observations = old_p->observations;
  old_p->observations.clear();
  old_p->bad = true;
  old_p->replaced_by = by;
  old_p->retired_at = map_.next_keyframe_id_;
  for (const auto& [kid, feature] : observations) {
    Keyframe* kf = keyframe(kid);
    if (kf == nullptr) continue;
    auto& slot = kf->points[static_cast<std::size_t>(feature)];
    if (!new_p->observations.contains(kid)) {
      new_p->observations[kid] = feature;
      slot = by;
    } else {
      slot = kNoPoint;
    }
  }
  new_p->visible += old_p->visible;
  new_p->found += old_p->found;
  update_point_descriptor(by);
}

void MapView::update_point_descriptor(PointId pid) {
  MapPoint* p = point(pid);
  if (p == nullptr || p->bad || p->observations.empty()) return;
  std::vector<cv::Mat> descs;
  std::vector<const std::uint8_t*> rows;
  for (const auto& [kid, feature] : p->observations) {
    const Keyframe* kf = keyframe(kid);
    if (kf == nullptr || kf->bad) continue;
    descs.push_back(kf->features.descriptors.row(feature));
    rows.push_back(descs.back().ptr<std::uint8_t>());
  }
  if (descs.empty()) return;
  // The representative descriptor has the least median distance to the others.
  const auto best = static_cast<std::size_t>(feat::distinctive_descriptor_index(rows));
  p->descriptor = descs[best].clone();
}

void MapView::update_point_normal_and_depth(PointId pid, const ScalePyramid& pyramid) {
  MapPoint* p = point(pid);
  if (p == nullptr || p->bad || p->observations.empty()) return;
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  int n = 0;
  for (const auto& [kid, feature] : p->observations) {
    const Keyframe* kf = keyframe(kid);
    if (kf == nullptr) continue;
    normal += (p->position - kf->camera_center()).normalized();
    ++n;
  }
  const Keyframe* ref = keyframe(p->reference);
  if (n == 0 || ref == nullptr) return;
  p->normal = normal.normalized();
  const double dist = (p->position - ref->camera_center()).norm();
  const int level =
      ref->features.keypoints[static_cast<std::size_t>(p->observations.at(p->reference))].octave;
  const double level_scale =
      pyramid.scale[static_cast<std::size_t>(std::clamp(level, 0, pyramid.levels - 1))];
  p->max_distance = dist * level_scale;
  p->min_distance = p->max_distance / pyramid.scale.back();
}

void MapView::update_connections(KeyframeId kid, int min_weight) {
  Keyframe* kf = keyframe(kid);
  if (kf == nullptr || kf->bad) return;
  // Counted in a hash map, then visited by increasing id (as a std::map would, at a fraction of the
  // cost: the tracker runs this under its write-back view).
  std::unordered_map<KeyframeId, int> counts;
  for (PointId pid : kf->points) {
    const MapPoint* p = pid == kNoPoint ? nullptr : point(pid);
    if (p == nullptr || p->bad) continue;
    for (const auto& [other, feature] : p->observations) {
      if (other != kid) ++counts[other];
    }
  }
  std::vector<std::pair<KeyframeId, int>> counter(counts.begin(), counts.end());
  std::sort(counter.begin(), counter.end());
  // Drop old back edges, then add the new ones.
  for (const auto& [other, w] : kf->covisibility) {
    if (Keyframe* o = keyframe(other)) o->covisibility.erase(kid);
  }
  kf->covisibility.clear();
  KeyframeId best = kNoKeyframe;
  int best_weight = 0;
  for (const auto& [other, w] : counter) {
    Keyframe* o = keyframe(other);
    if (o == nullptr || o->bad) continue;
    if (w > best_weight) {
      best_weight = w;
      best = other;
    }
    if (w >= min_weight) {
      kf->covisibility[other] = w;
      o->covisibility[kid] = w;
    }
  }
  // Always keep the strongest link so no keyframe is left unconnected.
  if (best != kNoKeyframe && kf->covisibility.empty()) {
    kf->covisibility[best] = best_weight;
    keyframe(best)->covisibility[kid] = best_weight;
  }
  if (kf->parent == kNoKeyframe && best != kNoKeyframe && best < kid) {
    kf->parent = best;
    keyframe(best)->children.insert(kid);
  }
}

std::vector<KeyframeId> MapReader::best_covisibles(KeyframeId kid, std::size_t n) const {
  const auto it = map_.keyframes_.find(kid);
  if (it == map_.keyframes_.end()) return {};
  std::vector<std::pair<int, KeyframeId>> v;
  for (const auto& [other, w] : it->second.covisibility) v.emplace_back(w, other);
  // Ties broken by id so the order is deterministic.
  std::sort(v.begin(), v.end(), [](const auto& a, const auto& b) {
    return a.first != b.first ? a.first > b.first : a.second < b.second;
  });
  std::vector<KeyframeId> out;
  for (std::size_t i = 0; i < v.size() && i < n; ++i) out.push_back(v[i].second);
  return out;
}

std::vector<KeyframeId> MapReader::covisibles_with_weight(KeyframeId kid, int min_weight) const {
  std::vector<KeyframeId> out;
  for (KeyframeId o : best_covisibles(kid, std::numeric_limits<std::size_t>::max())) {
    if (map_.keyframes_.at(kid).covisibility.at(o) >= min_weight) out.push_back(o);
  }
  return out;
}

int MapReader::tracked_points(KeyframeId kid, int min_observations) const {
  const auto it = map_.keyframes_.find(kid);
  if (it == map_.keyframes_.end()) return 0;
  int n = 0;
  for (PointId pid : it->second.points) {
    if (pid == kNoPoint) continue;
    const auto pit = map_.points_.find(pid);
    if (pit == map_.points_.end() || pit->second.bad) continue;
    // Only whether it reaches the threshold matters: this runs under the tracker's write-back view.
    if (weighted_observations_upto(map_.keyframes_, pit->second, min_observations) >= min_observations) ++n;
  }
  return n;
}

int MapReader::weighted_observations(const MapPoint& p) const {
  return weighted_observations_upto(map_.keyframes_, p, std::numeric_limits<int>::max());
}

bool MapView::hold_keyframe(KeyframeId kid) {
  Keyframe* kf = keyframe(kid);
  if (kf == nullptr || kf->bad) return false;
  ++kf->culling_holds;
  return true;
}

void MapView::release_keyframe(KeyframeId kid) {
  Keyframe* kf = keyframe(kid);
  if (kf == nullptr || kf->culling_holds <= 0) throw Error("map: release_keyframe without a hold");
  --kf->culling_holds;
}

bool MapView::erase_keyframe(KeyframeId kid) {
  Keyframe* kf = keyframe(kid);
  // The root keyframe stays; a held one is still in use by another stage.
  if (kf == nullptr || kf->bad || kf->parent == kNoKeyframe || kf->culling_holds > 0) return false;
  for (const auto& [other, w] : kf->covisibility) {
    if (Keyframe* o = keyframe(other)) o->covisibility.erase(kid);
  }
  for (std::size_t i = 0; i < kf->points.size(); ++i) {
    if (kf->points[i] != kNoPoint) erase_observation(kf->points[i], kid);
  }
  kf->T_c_parent = kf->T_cw * keyframe(kf->parent)->T_cw.inverse();
  // Re-parent children to the parent's side: each child takes its best covisible keyframe that is
  // already in the tree, falling back to this keyframe's parent.
  const KeyframeId parent = kf->parent;
  const auto children = kf->children;
  for (KeyframeId c : children) {
    Keyframe* child = keyframe(c);
    if (child == nullptr || child->bad) continue;
    KeyframeId new_parent = parent;
    for (KeyframeId cand : best_covisibles(c, 10)) {
      if (cand != kid && cand < c && keyframe(cand) != nullptr && !keyframe(cand)->bad) {
        new_parent = cand;
        break;
      }
    }
    child->parent = new_parent;
    keyframe(new_parent)->children.insert(c);
  }
  if (Keyframe* p = keyframe(parent)) p->children.erase(kid);
  kf->covisibility.clear();
  kf->children.clear();
  kf->bad = true;
  kf->retired_at = map_.next_keyframe_id_;
  return true;
}

const std::unordered_map<KeyframeId, Keyframe>& MapReader::keyframes() const { return map_.keyframes_; }
const std::unordered_map<PointId, MapPoint>& MapReader::points() const { return map_.points_; }

std::vector<KeyframeId> MapReader::keyframe_ids_sorted() const {
  std::vector<KeyframeId> ids;
  for (const auto& [id, kf] : map_.keyframes_) {
    if (!kf.bad) ids.push_back(id);
  }
  std::sort(ids.begin(), ids.end());
  return ids;
}

std::size_t MapReader::live_keyframes() const {
  return static_cast<std::size_t>(std::count_if(map_.keyframes_.begin(), map_.keyframes_.end(),
                                                [](const auto& kv) { return !kv.second.bad; }));
}

std::size_t MapReader::live_keyframes(MapId m) const {
  return static_cast<std::size_t>(
      std::count_if(map_.keyframes_.begin(), map_.keyframes_.end(),
                    [m](const auto& kv) { return !kv.second.bad && kv.second.map_id == m; }));
}

KeyframeId MapReader::map_root(MapId m) const {
  KeyframeId root = kNoKeyframe;
  for (const auto& [id, kf] : map_.keyframes_) {
    if (!kf.bad && kf.map_id == m && (root == kNoKeyframe || id < root)) root = id;
  }
  return root;
}

std::vector<MapId> MapReader::live_maps() const {
  std::vector<MapId> maps;
  for (const auto& [id, kf] : map_.keyframes_) {
    if (!kf.bad && std::find(maps.begin(), maps.end(), kf.map_id) == maps.end()) maps.push_back(kf.map_id);
  }
  std::sort(maps.begin(), maps.end());
  return maps;
}

std::size_t MapReader::live_points() const {
  return static_cast<std::size_t>(
      std::count_if(map_.points_.begin(), map_.points_.end(), [](const auto& kv) { return !kv.second.bad; }));
}

std::pair<KeyframeId, PointId> MapReader::next_ids() const {
  return {map_.next_keyframe_id_, map_.next_point_id_};
}

void MapView::restore(std::vector<Keyframe> keyframes, std::vector<MapPoint> points,
                      KeyframeId next_keyframe_id, PointId next_point_id) {
  if (!map_.keyframes_.empty() || !map_.points_.empty())
    throw Error("map: restore into a map that is not empty");
  std::unordered_map<KeyframeId, Keyframe> kfs;
  std::unordered_map<PointId, MapPoint> pts;
  for (Keyframe& kf : keyframes) {
    const KeyframeId id = kf.id;
    if (id == kNoKeyframe || id >= next_keyframe_id || !kfs.emplace(id, std::move(kf)).second)
      throw Error("map: restore with a keyframe id that is 0, repeated or not below the id counter");
  }
  for (MapPoint& p : points) {
    const PointId id = p.id;
    if (id == kNoPoint || id >= next_point_id || !pts.emplace(id, std::move(p)).second)
      throw Error("map: restore with a point id that is 0, repeated or not below the id counter");
  }
  map_.keyframes_ = std::move(kfs);
  map_.points_ = std::move(pts);
  map_.next_keyframe_id_ = next_keyframe_id;
  map_.next_point_id_ = next_point_id;
}

std::size_t MapView::purge_bad(KeyframeId retired_before) {
  const auto retired = [&](bool bad, KeyframeId at) {
    return bad && at != kNoKeyframe && at < retired_before;
  };
  std::size_t purged = std::erase_if(
      map_.points_, [&](const auto& kv) { return retired(kv.second.bad, kv.second.retired_at); });
  for (auto& [id, kf] : map_.keyframes_) {
    if (!retired(kf.bad, kf.retired_at) || (kf.features.size() == 0 && kf.thumbnail.empty())) continue;
    kf.features = FeatureSet{};
    kf.index = feat::FeatureGrid{};
    kf.points = std::vector<PointId>{};
    kf.thumbnail.release();
    kf.loop_edges.clear();
    ++purged;
  }
  return purged;
}

std::size_t MapView::merge_map(MapId from, MapId into, const geo::SE3& S_into_from, KeyframeId link_from,
                               KeyframeId link_into) {
  // Points first: they belong to `from` when the keyframe that made them (or any observer) does.
  auto in_from = [&](KeyframeId k) {
    const Keyframe* kf = keyframe(k);
    return kf != nullptr && kf->map_id == from;
  };
  for (auto& [pid, p] : map_.points_) {
    bool moves = in_from(p.reference) || in_from(p.first_keyframe);
    for (auto it = p.observations.begin(); !moves && it != p.observations.end(); ++it)
      moves = in_from(it->first);
    if (moves) p.position = S_into_from * p.position;
  }
  const geo::SE3 S_from_into = S_into_from.inverse();
  std::size_t moved = 0;
  KeyframeId root = kNoKeyframe;
  for (auto& [kid, kf] : map_.keyframes_) {
    if (kf.map_id != from) continue;
    kf.T_cw = kf.T_cw * S_from_into;
    kf.map_id = into;
    ++moved;
    if (kf.parent == kNoKeyframe && (root == kNoKeyframe || kid < root)) root = kid;
  }
  Keyframe* link = keyframe(link_into);
  if (root != kNoKeyframe && link != nullptr && root != link_into) {
    keyframe(root)->parent = link_into;
    link->children.insert(root);
  }
  if (Keyframe* a = keyframe(link_from); a != nullptr && link != nullptr && link_from != link_into) {
    a->loop_edges.insert(link_into);
    link->loop_edges.insert(link_from);
  }
  return moved;
}

}  // namespace sp::map
