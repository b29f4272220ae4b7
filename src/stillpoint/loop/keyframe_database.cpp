#include "stillpoint/loop/keyframe_database.hpp"

#include <algorithm>
#include <cmath>

namespace sp::loop {

void KeyframeDatabase::add(KeyframeId id, const BowVector& bow) {
  std::lock_guard lock(mutex_);
  if (auto it = vectors_.find(id); it != vectors_.end()) {
    for (const auto& [word, w] : it->second) std::erase(inverted_[word], id);
  }
  for (const auto& [word, w] : bow) {
    if (word >= inverted_.size()) inverted_.resize(std::size_t{word} + 1);
    inverted_[word].push_back(id);
  }
  vectors_[id] = bow;
}

void KeyframeDatabase::erase(KeyframeId id) {
  std::lock_guard lock(mutex_);
  const auto it = vectors_.find(id);
  if (it == vectors_.end()) return;
  for (const auto& [word, w] : it->second) std::erase(inverted_[word], id);
  vectors_.erase(it);
}

void KeyframeDatabase::clear() {
  std::lock_guard lock(mutex_);
  inverted_.clear();
  vectors_.clear();
}

bool KeyframeDatabase::contains(KeyframeId id) const {
  std::lock_guard lock(mutex_);
  return vectors_.contains(id);
}

std::size_t KeyframeDatabase::size() const {
  std::lock_guard lock(mutex_);
  return vectors_.size();
}

std::optional<double> KeyframeDatabase::score(KeyframeId id, const BowVector& bow) const {
  std::lock_guard lock(mutex_);
  const auto it = vectors_.find(id);
  if (it == vectors_.end()) return std::nullopt;
  ++scored_;
  return l1_score(it->second, bow);
}

std::optional<BowVector> KeyframeDatabase::bow(KeyframeId id) const {
  std::lock_guard lock(mutex_);
  const auto it = vectors_.find(id);
  if (it == vectors_.end()) return std::nullopt;
  return it->second;
}

std::vector<DatabaseHit> KeyframeDatabase::query(const BowVector& query, double min_common_ratio,
                                                 const std::function<bool(KeyframeId)>& exclude) const {
  std::lock_guard lock(mutex_);
  ++queries_;
  std::unordered_map<KeyframeId, std::uint32_t> common;
  std::unordered_map<KeyframeId, bool> excluded;  // memoises `exclude`, which may be costly
  for (const auto& [word, w] : query) {
    if (word >= inverted_.size()) continue;
    for (KeyframeId id : inverted_[word]) {
      auto [ex, fresh] = excluded.try_emplace(id, false);
      if (fresh && exclude) ex->second = exclude(id);
      if (!ex->second) ++common[id];
    }
  }
  std::uint32_t max_common = 0;
  for (const auto& [id, n] : common) max_common = std::max(max_common, n);
  const auto min_common = static_cast<std::uint32_t>(std::ceil(min_common_ratio * max_common));
  std::vector<DatabaseHit> hits;
  for (const auto& [id, n] : common) {
    if (n < min_common) continue;
    hits.push_back({id, n, l1_score(vectors_.at(id), query)});
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
