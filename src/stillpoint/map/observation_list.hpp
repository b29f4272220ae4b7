#pragma once
// A map point's observations (keyframe id -> feature index), kept as one sorted array instead of a
// std::map: the tracker walks the observations of every matched point under the map lock (local
// keyframes, covisibility of a new keyframe) and a red-black tree's node hops were most of that time
// (docs/map_lock.md). Same interface and the same iteration order (by increasing keyframe id) as the
// std::map it replaces, so results do not change; unlike a std::map, inserting or erasing invalidates
// iterators.
#include <algorithm>
#include <cstddef>
#include <initializer_list>
#include <stdexcept>
#include <utility>
#include <vector>

#include "stillpoint/map/types.hpp"

namespace sp::map {

class ObservationList {
 public:
  using value_type = std::pair<KeyframeId, int>;
  using iterator = std::vector<value_type>::iterator;
  using const_iterator = std::vector<value_type>::const_iterator;

  ObservationList() = default;
  // Later entries for the same keyframe are ignored, as std::map's initializer-list constructor does.
  ObservationList(std::initializer_list<value_type> entries) {
    for (const auto& [kf, feature] : entries) emplace(kf, feature);
  }

  [[nodiscard]] iterator begin() { return entries_.begin(); }
  [[nodiscard]] iterator end() { return entries_.end(); }
  [[nodiscard]] const_iterator begin() const { return entries_.begin(); }
  [[nodiscard]] const_iterator end() const { return entries_.end(); }
  [[nodiscard]] std::size_t size() const { return entries_.size(); }
  [[nodiscard]] bool empty() const { return entries_.empty(); }
  void clear() { entries_.clear(); }

  [[nodiscard]] iterator find(KeyframeId kf) {
    const auto it = lower_bound(kf);
    return it != entries_.end() && it->first == kf ? it : entries_.end();
  }
  [[nodiscard]] const_iterator find(KeyframeId kf) const {
    const auto it = lower_bound(kf);
    return it != entries_.end() && it->first == kf ? it : entries_.end();
  }
  [[nodiscard]] bool contains(KeyframeId kf) const { return find(kf) != end(); }

  [[nodiscard]] int& at(KeyframeId kf) {
    const auto it = find(kf);
    if (it == end()) throw std::out_of_range("ObservationList::at: keyframe not observed");
    return it->second;
  }
  [[nodiscard]] const int& at(KeyframeId kf) const {
    const auto it = find(kf);
    if (it == end()) throw std::out_of_range("ObservationList::at: keyframe not observed");
    return it->second;
  }
  // The feature for kf, inserted as 0 when kf is not there (std::map::operator[]).
  int& operator[](KeyframeId kf) { return emplace(kf, 0).first->second; }

  // Inserts (kf, feature) unless kf is there; the entry for kf and whether it was inserted.
  std::pair<iterator, bool> emplace(KeyframeId kf, int feature) {
    const auto it = lower_bound(kf);
    if (it != entries_.end() && it->first == kf) return {it, false};
    return {entries_.insert(it, value_type{kf, feature}), true};
  }
  iterator erase(const_iterator it) { return entries_.erase(it); }
  std::size_t erase(KeyframeId kf) {
    const auto it = find(kf);
    if (it == end()) return 0;
    entries_.erase(it);
    return 1;
  }

  friend bool operator==(const ObservationList&, const ObservationList&) = default;

 private:
  [[nodiscard]] iterator lower_bound(KeyframeId kf) {
    return std::lower_bound(entries_.begin(), entries_.end(), kf,
                            [](const value_type& e, KeyframeId k) { return e.first < k; });
  }
  [[nodiscard]] const_iterator lower_bound(KeyframeId kf) const {
    return std::lower_bound(entries_.begin(), entries_.end(), kf,
                            [](const value_type& e, KeyframeId k) { return e.first < k; });
  }

  std::vector<value_type> entries_;  // sorted by keyframe id, one entry per keyframe
};

}  // namespace sp::map
