#include "stillpoint/loop/global_descriptor_detector.hpp"

#include <algorithm>
#include <unordered_set>

#include "stillpoint/common/error.hpp"

namespace sp::loop {

GlobalDescriptorLoopDetector::GlobalDescriptorLoopDetector(const LoopDetectorParams& params)
    : params_(params), consistency_(params.min_consistency) {
  params_.validate();
}

void GlobalDescriptorLoopDetector::add_keyframe(const KeyframeInfo& kf) {
  if (kf.global.size() == 0) return;
  std::lock_guard lock(mutex_);
  descriptors_[kf.id] = kf.global;
}

void GlobalDescriptorLoopDetector::erase_keyframe(KeyframeId id) {
  std::lock_guard lock(mutex_);
  descriptors_.erase(id);
}

std::size_t GlobalDescriptorLoopDetector::queries() const {
  std::lock_guard lock(mutex_);
  return stats_.queries;
}

DetectorStats GlobalDescriptorLoopDetector::stats() const {
  std::lock_guard lock(mutex_);
  return stats_;
}

std::vector<LoopCandidate> GlobalDescriptorLoopDetector::detect(const KeyframeInfo& query,
                                                                const CovisibilityView& view) {
  if (query.global.size() == 0) throw Error("netvlad loop detector: keyframe without a global descriptor");
  const std::vector<KeyframeId> connected = view.covisible(query.id, 0);
  std::lock_guard lock(mutex_);
  ++stats_.keyframes;
  const auto distance = [&](const Eigen::VectorXf& d) -> double {
    if (d.size() != query.global.size()) throw Error("netvlad loop detector: descriptor sizes differ");
    return static_cast<double>((d - query.global).squaredNorm());
  };
  // The farthest connected keyframe bounds how far a loop candidate may be (no neighbour filed: no query).
  double max_d = -1.0;
  for (KeyframeId c : connected) {
    const auto it = descriptors_.find(c);
    if (it != descriptors_.end()) max_d = std::max(max_d, distance(it->second));
  }
  std::vector<LoopCandidate> out;
  if (max_d >= 0.0) {
    ++stats_.queries;
    const double limit = std::min(max_d, params_.global.max_distance_sq);
    const std::unordered_set<KeyframeId> excluded(connected.begin(), connected.end());
    std::vector<std::pair<double, KeyframeId>> hits;
    for (const auto& [id, d] : descriptors_) {
      if (id == query.id || excluded.contains(id)) continue;
      ++stats_.scored_pairs;
      const double dist = distance(d);
      if (dist <= limit) hits.emplace_back(dist, id);
    }
    std::sort(hits.begin(), hits.end());
    if (hits.size() > static_cast<std::size_t>(params_.global.top_k))
      hits.resize(static_cast<std::size_t>(params_.global.top_k));
    std::vector<std::set<KeyframeId>> groups;
    for (const auto& [dist, id] : hits) {
      const auto cov = view.covisible(id, params_.group_size);
      std::set<KeyframeId> members(cov.begin(), cov.end());
      members.insert(id);
      groups.push_back(std::move(members));
    }
    const std::vector<bool> accepted = consistency_.update(groups);
    for (std::size_t i = 0; i < hits.size(); ++i) {
      // Score in (0, 1] so callers can rank as with BoW: 1 for identical descriptors.
      if (accepted[i]) out.push_back({query.id, hits[i].second, 1.0 - hits[i].first / 4.0});
    }
  } else {
    consistency_.update({});
  }
  stats_.candidates += out.size();
  descriptors_[query.id] = query.global;
  return out;
}

}  // namespace sp::loop
