#pragma once
// A DBoW2-style vocabulary tree over 256-bit ORB descriptors: hierarchical k-means++ with
// bitwise-majority centres, TF-IDF word weights (idf = log(N_images / n_i)) and L1-normalised BoW
// vectors scored with the L1 score (bow_vector.hpp). Written from the published method (no DBoW2
// in Debian).
//
// File format (.spv, little-endian), version 1:
//   magic "SPVOCAB1" (8 bytes), u32 version, u32 k, u32 levels, u32 node_count, u32 word_count,
//   u32 parent[node_count]          (root = 0xFFFFFFFF; parents are non-decreasing: breadth-first ids)
//   u8  descriptor[node_count][32]  (root's is zero)
//   f32 weight[node_count]          (idf of leaves, 0 for inner nodes)
//   u64 FNV-1a-64 checksum of every byte before it.
// Leaves are the words, numbered in node-id order. 10^6 words is about 44 MB and loads in one read.
#include <array>
#include <cstdint>
#include <filesystem>
#include <opencv2/core.hpp>
#include <vector>

#include "stillpoint/common/config_reader.hpp"
#include "stillpoint/loop/bow_vector.hpp"

namespace sp::loop {

inline constexpr int kDescriptorBytes = 32;  // ORB: 256 bits

struct VocabularyParams {
  int k = 10;               // branching factor [children per node], 2..32
  int levels = 5;           // depth of the tree below the root [levels], 1..8
  int max_iterations = 15;  // k-means iterations per node (stops earlier when stable) [count], 1..100

  static VocabularyParams from_yaml(const sp::ConfigReader& r);
  // Throws sp::Error on a value out of range.
  void validate() const;
};

// Hamming distance of two 32-byte descriptors.
int hamming256(const std::uint8_t* a, const std::uint8_t* b);

class Vocabulary {
 public:
  Vocabulary() = default;

  // descriptors_per_image: one N x 32 CV_8U matrix per training image (empty ones are skipped).
  // Deterministic for a given seed. Throws sp::Error when there are no descriptors.
  static Vocabulary train(const std::vector<cv::Mat>& descriptors_per_image, const VocabularyParams& params,
                          std::uint32_t seed);

  // BoW vector (L1-normalised TF-IDF) of an image's N x 32 CV_8U descriptors, and its direct index:
  // each feature index is filed under its ancestor node `direct_index_levels_up` levels above its
  // word (0 = the word itself; levels below the root are clamped).
  void transform(const cv::Mat& descriptors, BowVector& bow, FeatureVector& direct_index,
                 int direct_index_levels_up) const;
  // Same without the direct index.
  [[nodiscard]] BowVector transform(const cv::Mat& descriptors) const;

  // Greedy descent: at each level the child whose centre is nearest (ties: lowest id).
  [[nodiscard]] WordId word_of(const std::uint8_t* descriptor) const;
  // The leaf node of a word and the word's idf weight.
  [[nodiscard]] NodeId node_of_word(WordId word) const { return word_nodes_.at(word); }
  [[nodiscard]] double word_weight(WordId word) const { return weight_.at(word_nodes_.at(word)); }
  [[nodiscard]] const std::uint8_t* node_descriptor(NodeId node) const {
    return &desc_.at(std::size_t{node} * kDescriptorBytes);
  }
  // Children of a node (contiguous ids; empty for a word) and its depth (root = 0).
  [[nodiscard]] std::vector<NodeId> children(NodeId node) const;
  [[nodiscard]] int depth(NodeId node) const { return depth_.at(node); }

  static double score(const BowVector& a, const BowVector& b) { return l1_score(a, b); }

  [[nodiscard]] std::size_t size() const noexcept { return word_nodes_.size(); }  // number of words
  [[nodiscard]] std::size_t node_count() const noexcept { return parent_.size(); }
  [[nodiscard]] int branching() const noexcept { return k_; }
  [[nodiscard]] int levels() const noexcept { return levels_; }
  [[nodiscard]] bool empty() const noexcept { return word_nodes_.empty(); }

  void save(const std::filesystem::path& file) const;
  // Throws sp::InputError naming the file when it is missing, truncated, corrupt or of another version.
  static Vocabulary load(const std::filesystem::path& file);

  bool operator==(const Vocabulary&) const = default;

 private:
  // Rebuilds children ranges, depths and word numbering from parent_ (after train or load).
  void index_tree();
  [[nodiscard]] NodeId leaf_of(const std::uint8_t* descriptor, NodeId* ancestor, int ancestor_depth) const;

  int k_ = 0;
  int levels_ = 0;
  std::vector<std::uint32_t> parent_;  // per node; root = kNoParent
  std::vector<std::uint8_t> desc_;     // node_count x 32
  std::vector<float> weight_;          // per node: idf for leaves
  // Derived (not saved):
  std::vector<std::uint32_t> first_child_;  // per node; children are contiguous ids
  std::vector<std::uint32_t> n_children_;
  std::vector<std::uint8_t> depth_;   // root = 0
  std::vector<WordId> word_of_node_;  // leaves only; kNoWord otherwise
  std::vector<NodeId> word_nodes_;    // word -> leaf node
};

}  // namespace sp::loop
