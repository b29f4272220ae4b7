#include "stillpoint/loop/keyframe_database.hpp"

#include <algorithm>
#include <cmath>

namespace sp::loop {

void KeyframeDatabase::erase_locked(std::unordered_map<EntryId, Slot>::iterator it) {
  const Slot slot = it->second;
  Entry& e = entries_[slot];
  for (const auto& [word, w] : e.bow) std::erase(inverted_[word], slot);
  e = Entry{};
  free_slots_.push_back(slot);
  slot_of_.erase(it);
}

void KeyframeDatabase::add(EntryId id, const BowVector& bow) {
  std::lock_guard lock(mutex_);
  if (auto it = slot_of_.find(id); it != slot_of_.end()) erase_locked(it);
  Slot slot = 0;
  if (!free_slots_.empty()) {
    slot = free_slots_.back();
    free_slots_.pop_back();
  } else {
    slot = static_cast<Slot>(entries_.size());
    entries_.emplace_back();
  }
  for (const auto& [word, w] : bow) {
    if (word >= inverted_.size()) inverted_.resize(std::size_t{word} + 1);
    inverted_[word].push_back(slot);
  }
  entries_[slot] = Entry{id, bow};
  slot_of_.emplace(id, slot);
}

void KeyframeDatabase::erase(EntryId id) {
  std::lock_guard lock(mutex_);
  if (auto it = slot_of_.find(id); it != slot_of_.end()) erase_locked(it);
}

void KeyframeDatabase::clear() {
  std::lock_guard lock(mutex_);
  inverted_.clear();
  entries_.clear();
  free_slots_.clear();
  slot_of_.clear();
}

bool KeyframeDatabase::contains(EntryId id) const {
  std::lock_guard lock(mutex_);
  return slot_of_.contains(id);
}

std::size_t KeyframeDatabase::size() const {
  std::lock_guard lock(mutex_);
  return slot_of_.size();
}

std::optional<double> KeyframeDatabase::score(EntryId id, const BowVector& bow) const {
  std::lock_guard lock(mutex_);
  const auto it = slot_of_.find(id);
  if (it == slot_of_.end()) return std::nullopt;
  ++scored_;
  return l1_score(entries_[it->second].bow, bow);
}

std::optional<BowVector> KeyframeDatabase::bow(EntryId id) const {
  std::lock_guard lock(mutex_);
  const auto it = slot_of_.find(id);
  if (it == slot_of_.end()) return std::nullopt;
  return entries_[it->second].bow;
}

std::vector<DatabaseHit> KeyframeDatabase::query(const BowVector& query, double min_common_ratio,
                                                 const std::function<bool(EntryId)>& exclude) const {
  std::lock_guard lock(mutex_);
  ++queries_;
  enum : std::uint8_t { kUnknown, kKept, kExcluded };
  std::vector<std::uint32_t> common(entries_.size(), 0);
  std::vector<std::uint8_t> state(entries_.size(), kUnknown);  // memoises `exclude`, which may be costly
  for (const auto& [word, w] : query) {
    if (word >= inverted_.size()) continue;
    for (Slot slot : inverted_[word]) {
      if (state[slot] == kUnknown) state[slot] = exclude && exclude(entries_[slot].id) ? kExcluded : kKept;
      if (state[slot] == kKept) ++common[slot];
    }
  }
  const std::uint32_t max_common = common.empty() ? 0 : *std::max_element(common.begin(), common.end());
  const auto min_common =
      std::max<std::uint32_t>(1, static_cast<std::uint32_t>(std::ceil(min_common_ratio * max_common)));
  std::vector<DatabaseHit> hits;
  for (Slot slot = 0; slot < common.size(); ++slot) {
    if (common[slot] < min_common) continue;
    hits.push_back({entries_[slot].id, common[slot], l1_score(entries_[slot].bow, query)});
  }
  scored_ += hits.size();
  std::sort(hits.begin(), hits.end(), [](const DatabaseHit& a, const DatabaseHit& b) {
    return a.score != b.score ? a.score > b.score : a.id < b.id;
  });
  return hits;
}

std::size_t KeyframeDatabase::queries() const {
  std::lock_guard lock(mutex_);
  return queries_;
}

std::size_t KeyframeDatabase::scored_pairs() const {
  std::lock_guard lock(mutex_);
  return scored_;
}

}  // namespace sp::loop
