#pragma once
// Loop-candidate detection by a learned global image descriptor (ParC_NetVLAD, src/stillpoint/place)
// instead of BoW: nearest keyframes in descriptor space, with the same safeguards as ORB-SLAM's BoW
// detector, read in distances. Map- and model-agnostic: the caller computes KeyframeInfo::global.
//  * A candidate must be at least as close to the query as the farthest keyframe already connected to
//    it (the BoW detector's "minimum score" rule), and within max_distance_sq absolutely.
//  * Connected (covisible) keyframes are never candidates.
//  * The top_k nearest survivors each stand for their covisibility group; a group must persist over
//    min_consistency consecutive queries (GroupConsistency), as in per-keyframe BoW detection.
#include <mutex>
#include <unordered_map>

#include "stillpoint/loop/loop_detector.hpp"

namespace sp::loop {

class GlobalDescriptorLoopDetector final : public LoopDetector {
 public:
  explicit GlobalDescriptorLoopDetector(const LoopDetectorParams& params);
  // Keyframes without a descriptor (empty `global`) are ignored.
  void add_keyframe(const KeyframeInfo& kf) override;
  void erase_keyframe(KeyframeId id) override;
  std::vector<LoopCandidate> detect(const KeyframeInfo& query, const CovisibilityView& view) override;
  std::vector<LoopCandidate> finish(const CovisibilityView&) override { return {}; }
  [[nodiscard]] std::size_t queries() const override;
  [[nodiscard]] DetectorStats stats() const override;
  [[nodiscard]] std::string name() const override { return "netvlad"; }
  [[nodiscard]] bool uses_global_descriptors() const override { return true; }

 private:
  LoopDetectorParams params_;
  mutable std::mutex mutex_;
  std::unordered_map<KeyframeId, Eigen::VectorXf> descriptors_;
  GroupConsistency consistency_;
  DetectorStats stats_;
};

}  // namespace sp::loop
