#include "stillpoint/loop/hybrid_detector.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "stillpoint/common/error.hpp"

namespace sp::loop {

HybridLoopDetector::HybridLoopDetector(const LoopDetectorParams& params) : params_(params) {
  params_.validate();
  bow_ = make_loop_detector(params_.hybrid.bow, params_);
}

void HybridLoopDetector::remember(const KeyframeInfo& kf) {
  if (kf.global.size() == 0) return;
  std::lock_guard lock(mutex_);
  descriptors_[kf.id] = kf.global;
}

void HybridLoopDetector::add_keyframe(const KeyframeInfo& kf) {
  remember(kf);
  bow_->add_keyframe(kf);
}

void HybridLoopDetector::erase_keyframe(KeyframeId id) {
  bow_->erase_keyframe(id);
  std::lock_guard lock(mutex_);
  descriptors_.erase(id);
}

std::vector<LoopCandidate> HybridLoopDetector::detect(const KeyframeInfo& query,
                                                      const CovisibilityView& view) {
  remember(query);
  auto candidates = bow_->detect(query, view);
  std::lock_guard lock(mutex_);
  return rerank(std::move(candidates));
}

std::vector<LoopCandidate> HybridLoopDetector::finish(const CovisibilityView& view) {
  auto candidates = bow_->finish(view);
  std::lock_guard lock(mutex_);
  return rerank(std::move(candidates));
}

std::vector<LoopCandidate> HybridLoopDetector::rerank(std::vector<LoopCandidate> candidates) {
  constexpr double kUndescribed = std::numeric_limits<double>::infinity();
  std::vector<std::pair<double, LoopCandidate>> scored;
  scored.reserve(candidates.size());
  for (const LoopCandidate& c : candidates) {
    const auto q = descriptors_.find(c.query);
    const auto m = descriptors_.find(c.match);
    double d2 = kUndescribed;
    if (q != descriptors_.end() && m != descriptors_.end()) {
      if (q->second.size() != m->second.size()) throw Error("hybrid loop detector: descriptor sizes differ");
      d2 = static_cast<double>((q->second - m->second).squaredNorm());
    }
    if (!std::isfinite(d2)) {  // no descriptor, or a broken one (NaN): BoW decides, after the described
      ++undescribed_;
      scored.emplace_back(kUndescribed, c);
      continue;
    }
    ++scored_pairs_;
    spdlog::debug("hybrid: candidate {} -> {} (BoW score {:.3f}) descriptor d² {:.3f}{}", c.query, c.match,
                  c.score, d2, d2 > params_.hybrid.max_distance_sq ? " vetoed" : "");
    if (d2 > params_.hybrid.max_distance_sq) {
      ++vetoed_;
      continue;
    }
    scored.emplace_back(d2, c);
  }
  // Stable: equal distances (and the undescribed) keep BoW's order.
  std::stable_sort(scored.begin(), scored.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<LoopCandidate> out;
  out.reserve(scored.size());
  for (auto& [d2, c] : scored) out.push_back(c);
  return out;
}

std::size_t HybridLoopDetector::queries() const { return bow_->queries(); }

DetectorStats HybridLoopDetector::stats() const {
  DetectorStats s = bow_->stats();
  std::lock_guard lock(mutex_);
  s.candidates -= std::min(s.candidates, vetoed_);
  s.descriptor_pairs = scored_pairs_;
  s.vetoed_by_descriptor = vetoed_;
  s.undescribed_candidates = undescribed_;
  return s;
}

}  // namespace sp::loop
