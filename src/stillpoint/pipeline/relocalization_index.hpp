#pragma once
// The keyframe BoW database that global relocalisation queries, kept in every run: each keyframe is
// filed once local mapping (or loop closing, which computes the keyframe's BoW vector anyway) has
// processed it, and erased when the map culls it. Thread-safe (the database's and its own mutex, both
// leaves: callers may hold a map view).
#include <cstddef>
#include <functional>
#include <memory>
#include <mutex>
#include <set>
#include <vector>

#include "stillpoint/loop/keyframe_database.hpp"
#include "stillpoint/loop/vocabulary.hpp"
#include "stillpoint/map/map.hpp"

namespace sp::pipeline {

struct RelocalizationIndexStats {
  std::size_t filed = 0;    // keyframes filed over the run
  std::size_t erased = 0;   // ... erased again because the map culled them
  std::size_t queries = 0;  // relocalisation queries
};

class RelocalizationIndex {
 public:
  explicit RelocalizationIndex(std::shared_ptr<const loop::Vocabulary> vocabulary);

  [[nodiscard]] loop::BowVector describe(const cv::Mat& descriptors) const;
  // Files a keyframe's vector (replacing an earlier one of the same id).
  void add(map::KeyframeId id, const loop::BowVector& bow);
  // Erases the filed keyframes the map has culled (bad or purged); returns them, in id order.
  std::vector<map::KeyframeId> erase_culled(map::MapView& view);
  void erase(map::KeyframeId id);
  // ORB-SLAM's relocalisation query over every filed keyframe: those sharing at least 80 % of the most
  // shared words with the frame's descriptors, best L1 score first, at most `n`.
  // Keyframes `exclude` rejects are left out before the 80 % rule (map merging asks for other maps only).
  [[nodiscard]] std::vector<map::KeyframeId> candidates(
      const cv::Mat& descriptors, std::size_t n, const std::function<bool(map::KeyframeId)>& exclude = {});
  [[nodiscard]] std::size_t size() const;
  [[nodiscard]] RelocalizationIndexStats stats() const;

 private:
  std::shared_ptr<const loop::Vocabulary> vocabulary_;
  loop::KeyframeDatabase db_;
  mutable std::mutex mutex_;
  std::set<map::KeyframeId> filed_;
  RelocalizationIndexStats stats_;
};

}  // namespace sp::pipeline
