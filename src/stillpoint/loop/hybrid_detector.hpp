#pragma once
// Hybrid loop detection (issue 17): BoW finds the candidates, a learned global descriptor (ParC_NetVLAD)
// re-ranks them and vetoes those that do not look alike. BoW keeps its cheap inverted-file search and
// its group-consistency checks; the descriptor adds appearance evidence that ORB words lack (layout,
// colour, texture at large scale), so verification tries the most alike candidate first and skips
// candidates whose whole-image appearance disagrees.
//  * Candidates come from an inner "bow-keyframe" or "bow-sequence" detector, unchanged.
//  * Each is scored by d² between the descriptors of its query keyframe and its match (L2-normalised,
//    so d² is in [0, 4]); candidates with d² > max_distance_sq are dropped, the rest sorted by d².
//  * A candidate whose keyframes have no (finite) descriptor is kept, after the described ones (BoW
//    decides), and counted in DetectorStats::undescribed_candidates.
#include <memory>
#include <mutex>
#include <unordered_map>

#include "stillpoint/loop/loop_detector.hpp"

namespace sp::loop {

class HybridLoopDetector final : public LoopDetector {
 public:
  explicit HybridLoopDetector(const LoopDetectorParams& params);
  void add_keyframe(const KeyframeInfo& kf) override;
  void erase_keyframe(KeyframeId id) override;
  std::vector<LoopCandidate> detect(const KeyframeInfo& query, const CovisibilityView& view) override;
  std::vector<LoopCandidate> finish(const CovisibilityView& view) override;
  [[nodiscard]] std::size_t queries() const override;
  [[nodiscard]] DetectorStats stats() const override;
  [[nodiscard]] std::string name() const override { return "hybrid"; }
  [[nodiscard]] bool uses_global_descriptors() const override { return true; }

 private:
  void remember(const KeyframeInfo& kf);
  // Drops and re-orders the inner detector's candidates by descriptor distance (mutex held).
  std::vector<LoopCandidate> rerank(std::vector<LoopCandidate> candidates);

  LoopDetectorParams params_;
  std::unique_ptr<LoopDetector> bow_;  // thread-safe itself; called outside mutex_
  mutable std::mutex mutex_;
  std::unordered_map<KeyframeId, Eigen::VectorXf> descriptors_;
  std::size_t scored_pairs_ = 0;
  std::size_t vetoed_ = 0;
  std::size_t undescribed_ = 0;
};

}  // namespace sp::loop
