#include "stillpoint/pipeline/relocalization_index.hpp"

namespace sp::pipeline {

RelocalizationIndex::RelocalizationIndex(std::shared_ptr<const loop::Vocabulary> vocabulary)
    : vocabulary_(std::move(vocabulary)) {}

loop::BowVector RelocalizationIndex::describe(const cv::Mat& descriptors) const {
  return vocabulary_->transform(descriptors);
}

void RelocalizationIndex::add(map::KeyframeId id, const loop::BowVector& bow) {
  std::lock_guard lock(mutex_);
  db_.add(id.value(), bow);
  if (filed_.insert(id).second) ++stats_.filed;
}

void RelocalizationIndex::erase(map::KeyframeId id) {
  std::lock_guard lock(mutex_);
  if (filed_.erase(id) == 0) return;
  db_.erase(id.value());
  ++stats_.erased;
}

std::vector<map::KeyframeId> RelocalizationIndex::erase_culled(map::MapView& view) {
  std::lock_guard lock(mutex_);
  std::vector<map::KeyframeId> culled;
  for (map::KeyframeId id : filed_) {
    const map::Keyframe* kf = view.keyframe(id);
    if (kf == nullptr || kf->bad) culled.push_back(id);
  }
  for (map::KeyframeId id : culled) {
    filed_.erase(id);
    db_.erase(id.value());
  }
  stats_.erased += culled.size();
  return culled;
}

std::vector<map::KeyframeId> RelocalizationIndex::candidates(
    const cv::Mat& descriptors, std::size_t n, const std::function<bool(map::KeyframeId)>& exclude) {
  if (descriptors.empty()) return {};  // a black frame: nothing to look up
  const loop::BowVector bow = describe(descriptors);
  std::lock_guard lock(mutex_);
  ++stats_.queries;
  std::function<bool(loop::EntryId)> exclude_entry;
  if (exclude) exclude_entry = [&exclude](loop::EntryId id) { return exclude(map::KeyframeId{id}); };
  const auto hits = db_.query(bow, 0.8, exclude_entry);
  std::vector<map::KeyframeId> out;
  for (std::size_t i = 0; i < hits.size() && i < n; ++i) out.emplace_back(hits[i].id);
  return out;
}

std::size_t RelocalizationIndex::size() const {
  std::lock_guard lock(mutex_);
  return filed_.size();
}

RelocalizationIndexStats RelocalizationIndex::stats() const {
  std::lock_guard lock(mutex_);
  return stats_;
}

}  // namespace sp::pipeline
