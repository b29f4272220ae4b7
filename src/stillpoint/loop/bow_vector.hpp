#pragma once
// Bag-of-words vectors: sparse (word, weight) lists kept sorted by word, so that scoring two vectors
// is one linear merge. Weights are non-negative (TF-IDF), which the L1 score relies on.
#include <cstddef>
#include <cstdint>
#include <map>
#include <utility>
#include <vector>

namespace sp::loop {

using WordId = std::uint32_t;
using NodeId = std::uint32_t;

// Direct index: vocabulary node (at a chosen level) -> indices of the features that descend through it.
// Sorted by node, so two images' features under the same node can be matched node by node.
using FeatureVector = std::map<NodeId, std::vector<std::uint32_t>>;

class BowVector {
 public:
  using Entry = std::pair<WordId, double>;

  BowVector() = default;
  // Sorts the entries and sums the weights of repeated words. Negative weights are an sp::Error.
  static BowVector from_entries(std::vector<Entry> entries);

  [[nodiscard]] const std::vector<Entry>& entries() const noexcept { return entries_; }
  [[nodiscard]] std::size_t size() const noexcept { return entries_.size(); }
  [[nodiscard]] bool empty() const noexcept { return entries_.empty(); }
  [[nodiscard]] auto begin() const noexcept { return entries_.begin(); }
  [[nodiscard]] auto end() const noexcept { return entries_.end(); }
  // Weight of `word`, 0 when absent (binary search).
  [[nodiscard]] double weight(WordId word) const;
  // Kept with the vector: every score needs both norms, and summed sequence vectors are long.
  [[nodiscard]] double l1_norm() const noexcept { return l1_norm_; }
  // Scales the weights to sum 1 (no-op for an empty or all-zero vector).
  void normalize_l1();

  bool operator==(const BowVector&) const = default;

 private:
  std::vector<Entry> entries_;  // sorted by word, unique words, weights >= 0
  double l1_norm_ = 0.0;        // sum of the weights
};

// DBoW2's L1 score s = 1 - 1/2 |a/|a| - b/|b||_1, in [0, 1]; 0 when either vector is empty.
// For non-negative weights this equals the sum over shared words of min(a_i/|a|, b_i/|b|).
double l1_score(const BowVector& a, const BowVector& b);

// Number of words present in both vectors.
std::size_t common_words(const BowVector& a, const BowVector& b);

// Normalised sum of L1-normalised vectors: each input counts equally, whatever its own scale.
BowVector normalized_sum(const std::vector<const BowVector*>& vectors);

}  // namespace sp::loop
