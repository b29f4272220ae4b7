#include "stillpoint/loop/vocabulary.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <deque>
#include <fstream>
#include <limits>
#include <random>
#include <tuple>
#include <unordered_set>

#include "stillpoint/common/error.hpp"
#include "stillpoint/features/descriptor.hpp"

namespace sp::loop {
namespace {

constexpr std::uint32_t kNoParent = std::numeric_limits<std::uint32_t>::max();
constexpr WordId kNoWord = std::numeric_limits<WordId>::max();
constexpr char kMagic[8] = {'S', 'P', 'V', 'O', 'C', 'A', 'B', '1'};
constexpr std::uint32_t kVersion = 1;
constexpr std::size_t kHeaderBytes = 8 + 5 * 4;

std::uint64_t fnv1a64(const char* data, std::size_t n) {
  std::uint64_t h = 14695981039346656037ULL;
  for (std::size_t i = 0; i < n; ++i) {
    h ^= static_cast<std::uint8_t>(data[i]);
    h *= 1099511628211ULL;
  }
  return h;
}

template <typename T>
void put(std::vector<char>& buf, const T& v) {
  const auto* p = reinterpret_cast<const char*>(&v);
  buf.insert(buf.end(), p, p + sizeof(T));
}

// A cluster of training descriptors (indices into the flat training array) and its centre.
struct Cluster {
  std::array<std::uint8_t, kDescriptorBytes> centre{};
  std::vector<std::uint32_t> members;
};

void majority_centre(const std::vector<std::uint8_t>& all, const std::vector<std::uint32_t>& members,
                     std::uint8_t* centre) {
  std::array<std::uint32_t, kDescriptorBytes * 8> ones{};
  for (std::uint32_t m : members) {
    const std::uint8_t* d = &all[std::size_t{m} * kDescriptorBytes];
    for (int j = 0; j < kDescriptorBytes; ++j) {
      for (int b = 0; b < 8; ++b) ones[j * 8 + b] += (d[j] >> b) & 1U;
    }
  }
  const std::size_t n = members.size();
  for (int j = 0; j < kDescriptorBytes; ++j) {
    std::uint8_t byte = 0;
    for (int b = 0; b < 8; ++b) {
      if (2 * std::size_t{ones[j * 8 + b]} > n) byte |= static_cast<std::uint8_t>(1U << b);
    }
    centre[j] = byte;
  }
}

// k-means++ seeding then Lloyd iterations with majority centres. Returns non-empty clusters only.
std::vector<Cluster> kmeans(const std::vector<std::uint8_t>& all, const std::vector<std::uint32_t>& members,
                            int k, int max_iterations, std::mt19937& rng) {
  const auto desc = [&](std::uint32_t m) { return &all[std::size_t{m} * kDescriptorBytes]; };
  std::vector<Cluster> clusters;
  if (members.size() <= static_cast<std::size_t>(k)) {
    // Few descriptors: one cluster per distinct descriptor.
    for (std::uint32_t m : members) {
      bool dup = false;
      for (auto& c : clusters) {
        if (std::memcmp(c.centre.data(), desc(m), kDescriptorBytes) == 0) {
          c.members.push_back(m);
          dup = true;
          break;
        }
      }
      if (!dup) {
        Cluster c;
        std::memcpy(c.centre.data(), desc(m), kDescriptorBytes);
        c.members.push_back(m);
        clusters.push_back(std::move(c));
      }
    }
    return clusters;
  }

  // Greedy k-means++ (as in scikit-learn): each step draws 2 + ln k candidates with probability
  // proportional to D^2 and keeps the one that lowers the total D^2 most. Plain k-means++ too often
  // puts two seeds in one natural cluster, which Lloyd iterations on a tree level cannot undo.
  std::vector<std::array<std::uint8_t, kDescriptorBytes>> centres;
  std::uniform_int_distribution<std::size_t> pick(0, members.size() - 1);
  centres.emplace_back();
  std::memcpy(centres.back().data(), desc(members[pick(rng)]), kDescriptorBytes);
  std::vector<double> d2(members.size());
  double total = 0.0;
  for (std::size_t i = 0; i < members.size(); ++i) {
    const double d = hamming256(desc(members[i]), centres.back().data());
    d2[i] = d * d;
    total += d2[i];
  }
  const int n_candidates = 2 + static_cast<int>(std::log(static_cast<double>(k)));
  std::vector<double> trial(members.size());
  std::vector<double> best_d2(members.size());
  while (centres.size() < static_cast<std::size_t>(k) && total > 0.0) {
    double best_total = std::numeric_limits<double>::max();
    std::size_t best_i = 0;
    for (int t = 0; t < n_candidates; ++t) {
      std::uniform_real_distribution<double> u(0.0, total);
      double r = u(rng);
      std::size_t chosen = members.size();
      for (std::size_t i = 0; i < members.size(); ++i) {
        r -= d2[i];
        if (r <= 0.0 && d2[i] > 0.0) {
          chosen = i;
          break;
        }
      }
      if (chosen == members.size()) {  // rounding at the end of the range: last point with D > 0
        for (std::size_t i = members.size(); i-- > 0;) {
          if (d2[i] > 0.0) {
            chosen = i;
            break;
          }
        }
      }
      double sum = 0.0;
      for (std::size_t i = 0; i < members.size(); ++i) {
        const double d = hamming256(desc(members[i]), desc(members[chosen]));
        trial[i] = std::min(d2[i], d * d);
        sum += trial[i];
      }
      if (sum < best_total) {
        best_total = sum;
        best_i = chosen;
        best_d2.swap(trial);
      }
    }
    centres.emplace_back();
    std::memcpy(centres.back().data(), desc(members[best_i]), kDescriptorBytes);
    d2.swap(best_d2);
    best_d2.resize(members.size());
    total = best_total;
  }

  std::vector<int> assign(members.size(), -1);
  for (int it = 0; it < max_iterations; ++it) {
    bool changed = false;
    for (std::size_t i = 0; i < members.size(); ++i) {
      int best = 0;
      int best_d = std::numeric_limits<int>::max();
      for (std::size_t c = 0; c < centres.size(); ++c) {
        const int d = hamming256(desc(members[i]), centres[c].data());
        if (d < best_d) {
          best_d = d;
          best = static_cast<int>(c);
        }
      }
      if (assign[i] != best) {
        assign[i] = best;
        changed = true;
      }
    }
    if (!changed) break;
    std::vector<std::vector<std::uint32_t>> groups(centres.size());
    for (std::size_t i = 0; i < members.size(); ++i) groups[assign[i]].push_back(members[i]);
    for (std::size_t c = 0; c < centres.size(); ++c) {
      if (!groups[c].empty()) majority_centre(all, groups[c], centres[c].data());
    }
  }
  clusters.resize(centres.size());
  for (std::size_t c = 0; c < centres.size(); ++c) clusters[c].centre = centres[c];
  for (std::size_t i = 0; i < members.size(); ++i) clusters[assign[i]].members.push_back(members[i]);
  std::erase_if(clusters, [](const Cluster& c) { return c.members.empty(); });
  return clusters;
}

}  // namespace

int hamming256(const std::uint8_t* a, const std::uint8_t* b) { return feat::hamming_distance(a, b); }

VocabularyParams VocabularyParams::from_yaml(const sp::ConfigReader& r) {
  VocabularyParams p;
  r.read("k", p.k, 2, 32);
  r.read("levels", p.levels, 1, 8);
  r.read("max_iterations", p.max_iterations, 1, 100);
  return p;
}

void VocabularyParams::validate() const {
  if (k < 2 || k > 32) throw sp::Error("vocabulary: k must be in [2, 32], got " + std::to_string(k));
  if (levels < 1 || levels > 8)
    throw sp::Error("vocabulary: levels must be in [1, 8], got " + std::to_string(levels));
  if (max_iterations < 1 || max_iterations > 100)
    throw sp::Error("vocabulary: max_iterations must be in [1, 100]");
}

Vocabulary Vocabulary::train(const std::vector<cv::Mat>& descriptors_per_image,
                             const VocabularyParams& params, std::uint32_t seed) {
  params.validate();
  std::vector<std::uint8_t> all;
  std::size_t n_images = 0;
  for (const cv::Mat& d : descriptors_per_image) {
    if (d.empty()) continue;
    if (d.type() != CV_8UC1 || d.cols != kDescriptorBytes) {
      throw sp::Error("Vocabulary::train: descriptors must be N x 32 CV_8U");
    }
    ++n_images;
    for (int r = 0; r < d.rows; ++r)
      all.insert(all.end(), d.ptr<std::uint8_t>(r), d.ptr<std::uint8_t>(r) + kDescriptorBytes);
  }
  const std::size_t n_desc = all.size() / kDescriptorBytes;
  if (n_desc == 0) throw sp::Error("Vocabulary::train: no descriptors");

  Vocabulary v;
  v.k_ = params.k;
  v.levels_ = params.levels;
  v.parent_.push_back(kNoParent);
  v.desc_.assign(kDescriptorBytes, 0);
  v.weight_.push_back(0.0F);

  struct Pending {
    NodeId node;
    int depth;
    std::vector<std::uint32_t> members;
  };
  std::deque<Pending> queue;
  std::vector<std::uint32_t> root_members(n_desc);
  for (std::size_t i = 0; i < n_desc; ++i) root_members[i] = static_cast<std::uint32_t>(i);
  queue.push_back({0, 0, std::move(root_members)});
  std::mt19937 rng(seed);
  // Breadth-first: nodes are split in id order, so children get contiguous ids and parents never decrease.
  while (!queue.empty()) {
    Pending p = std::move(queue.front());
    queue.pop_front();
    if (p.depth >= params.levels || p.members.size() <= 1) continue;
    std::vector<Cluster> clusters = kmeans(all, p.members, params.k, params.max_iterations, rng);
    if (clusters.size() <= 1 && p.node != 0) continue;  // identical descriptors: stays a leaf
    for (Cluster& c : clusters) {
      const auto child = static_cast<NodeId>(v.parent_.size());
      v.parent_.push_back(p.node);
      v.desc_.insert(v.desc_.end(), c.centre.begin(), c.centre.end());
      v.weight_.push_back(0.0F);
      queue.push_back({child, p.depth + 1, std::move(c.members)});
    }
  }
  v.index_tree();

  // idf from the images each word occurs in, as the greedy descent assigns them.
  std::vector<std::uint32_t> n_i(v.size(), 0);
  for (const cv::Mat& d : descriptors_per_image) {
    if (d.empty()) continue;
    std::unordered_set<WordId> seen;
    for (int r = 0; r < d.rows; ++r) seen.insert(v.word_of(d.ptr<std::uint8_t>(r)));
    for (WordId w : seen) ++n_i[w];
  }
  for (WordId w = 0; w < v.size(); ++w) {
    // Never-seen words keep weight 0 and are ignored by transform().
    if (n_i[w] > 0) {
      v.weight_[v.word_nodes_[w]] =
          static_cast<float>(std::log(static_cast<double>(n_images) / static_cast<double>(n_i[w])));
    }
  }
  spdlog::debug("vocabulary: {} descriptors from {} images -> {} nodes, {} words", n_desc, n_images,
                v.node_count(), v.size());
  return v;
}

void Vocabulary::index_tree() {
  const std::size_t n = parent_.size();
  first_child_.assign(n, 0);
  n_children_.assign(n, 0);
  depth_.assign(n, 0);
  word_of_node_.assign(n, kNoWord);
  word_nodes_.clear();
  for (std::size_t i = 1; i < n; ++i) {
    const std::uint32_t p = parent_[i];
    if (n_children_[p] == 0) first_child_[p] = static_cast<std::uint32_t>(i);
    ++n_children_[p];
    depth_[i] = static_cast<std::uint8_t>(depth_[p] + 1);
  }
  for (std::size_t i = 0; i < n; ++i) {
    if (n_children_[i] == 0 && i != 0) {
      word_of_node_[i] = static_cast<WordId>(word_nodes_.size());
      word_nodes_.push_back(static_cast<NodeId>(i));
    }
  }
}

NodeId Vocabulary::leaf_of(const std::uint8_t* descriptor, NodeId* ancestor, int ancestor_depth) const {
  NodeId node = 0;
  while (n_children_[node] > 0) {
    const std::uint32_t first = first_child_[node];
    const std::uint32_t last = first + n_children_[node];
    NodeId best = first;
    int best_d = std::numeric_limits<int>::max();
    for (std::uint32_t c = first; c < last; ++c) {
      const int d = hamming256(descriptor, &desc_[std::size_t{c} * kDescriptorBytes]);
      if (d < best_d) {
        best_d = d;
        best = c;
      }
    }
    node = best;
    if (ancestor != nullptr && depth_[node] <= ancestor_depth) *ancestor = node;
  }
  return node;
}

std::vector<NodeId> Vocabulary::children(NodeId node) const {
  std::vector<NodeId> out;
  for (std::uint32_t i = 0; i < n_children_.at(node); ++i) out.push_back(first_child_[node] + i);
  return out;
}

WordId Vocabulary::word_of(const std::uint8_t* descriptor) const {
  if (empty()) throw sp::Error("Vocabulary::word_of: empty vocabulary");
  return word_of_node_[leaf_of(descriptor, nullptr, 0)];
}

void Vocabulary::transform(const cv::Mat& descriptors, BowVector& bow, FeatureVector& direct_index,
                           int direct_index_levels_up) const {
  bow = BowVector();
  direct_index.clear();
  if (descriptors.empty()) return;
  if (empty()) throw sp::Error("Vocabulary::transform: empty vocabulary");
  if (descriptors.type() != CV_8UC1 || descriptors.cols != kDescriptorBytes) {
    throw sp::Error("Vocabulary::transform: descriptors must be N x 32 CV_8U");
  }
  const int ancestor_depth = std::max(1, levels_ - std::max(0, direct_index_levels_up));
  std::vector<BowVector::Entry> entries;
  entries.reserve(static_cast<std::size_t>(descriptors.rows));
  for (int r = 0; r < descriptors.rows; ++r) {
    NodeId ancestor = 0;
    const NodeId leaf = leaf_of(descriptors.ptr<std::uint8_t>(r), &ancestor, ancestor_depth);
    const double w = weight_[leaf];
    if (w <= 0.0) continue;  // a word seen in every training image (or never) carries no information
    entries.emplace_back(word_of_node_[leaf], w);
    direct_index[ancestor].push_back(static_cast<std::uint32_t>(r));
  }
  bow = BowVector::from_entries(std::move(entries));
  bow.normalize_l1();
}

BowVector Vocabulary::transform(const cv::Mat& descriptors) const {
  BowVector bow;
  FeatureVector fv;
  transform(descriptors, bow, fv, 0);
  return bow;
}

void Vocabulary::save(const std::filesystem::path& file) const {
  const auto n = static_cast<std::uint32_t>(parent_.size());
  std::vector<char> buf;
  buf.reserve(kHeaderBytes + std::size_t{n} * (4 + kDescriptorBytes + 4) + 8);
  buf.insert(buf.end(), std::begin(kMagic), std::end(kMagic));
  put(buf, kVersion);
  put(buf, static_cast<std::uint32_t>(k_));
  put(buf, static_cast<std::uint32_t>(levels_));
  put(buf, n);
  put(buf, static_cast<std::uint32_t>(word_nodes_.size()));
  const auto append = [&](const void* p, std::size_t bytes) {
    buf.insert(buf.end(), static_cast<const char*>(p), static_cast<const char*>(p) + bytes);
  };
  append(parent_.data(), parent_.size() * 4);
  append(desc_.data(), desc_.size());
  append(weight_.data(), weight_.size() * 4);
  put(buf, fnv1a64(buf.data(), buf.size()));
  std::ofstream out(file, std::ios::binary | std::ios::trunc);
  if (!out) throw sp::InputError(file.string(), 0, "cannot open the vocabulary file for writing");
  out.write(buf.data(), static_cast<std::streamsize>(buf.size()));
  if (!out) throw sp::InputError(file.string(), 0, "writing the vocabulary file failed");
}

Vocabulary Vocabulary::load(const std::filesystem::path& file) {
  const std::string name = file.string();
  const auto fail = [&](const std::string& what) -> void {
    throw sp::InputError(name, 0, "vocabulary: " + what);
  };
  std::error_code ec;
  const auto size = std::filesystem::file_size(file, ec);
  if (ec) fail("cannot read the file (" + ec.message() + ")");
  std::ifstream in(file, std::ios::binary);
  if (!in) fail("cannot open the file");
  std::vector<char> buf(size);
  in.read(buf.data(), static_cast<std::streamsize>(size));
  if (!in) fail("cannot read the file");

  if (size < kHeaderBytes + 8 || std::memcmp(buf.data(), kMagic, 8) != 0) {
    fail("not a StillPoint vocabulary (bad magic or too short)");
  }
  std::uint32_t hdr[5];
  std::memcpy(hdr, buf.data() + 8, sizeof(hdr));
  const auto [version, k, levels, n, n_words] = std::tuple{hdr[0], hdr[1], hdr[2], hdr[3], hdr[4]};
  if (version != kVersion) {
    fail("unsupported format version " + std::to_string(version) + " (this build reads version " +
         std::to_string(kVersion) + ")");
  }
  if (k < 2 || k > 32 || levels < 1 || levels > 8 || n < 2)
    fail("implausible header (k, levels or node count)");
  const std::size_t expected = kHeaderBytes + std::size_t{n} * (4 + kDescriptorBytes + 4) + 8;
  if (size != expected) {
    fail("file is " + std::to_string(size) + " bytes, the header implies " + std::to_string(expected) +
         " (truncated or corrupt)");
  }
  std::uint64_t stored = 0;
  std::memcpy(&stored, buf.data() + size - 8, 8);
  if (stored != fnv1a64(buf.data(), size - 8)) fail("checksum mismatch (corrupt file)");

  Vocabulary v;
  v.k_ = static_cast<int>(k);
  v.levels_ = static_cast<int>(levels);
  const char* p = buf.data() + kHeaderBytes;
  v.parent_.resize(n);
  std::memcpy(v.parent_.data(), p, std::size_t{n} * 4);
  p += std::size_t{n} * 4;
  v.desc_.resize(std::size_t{n} * kDescriptorBytes);
  std::memcpy(v.desc_.data(), p, v.desc_.size());
  p += v.desc_.size();
  v.weight_.resize(n);
  std::memcpy(v.weight_.data(), p, std::size_t{n} * 4);

  // Structural checks, so a well-checksummed but inconsistent file cannot crash the descent.
  if (v.parent_[0] != kNoParent) fail("node 0 is not the root");
  for (std::uint32_t i = 1; i < n; ++i) {
    if (v.parent_[i] >= i || (i > 1 && v.parent_[i] < v.parent_[i - 1])) fail("bad tree (parent order)");
  }
  for (float w : v.weight_) {
    if (!std::isfinite(w) || w < 0.0F) fail("bad word weight");
  }
  v.index_tree();
  for (std::uint32_t i = 0; i < n; ++i) {
    if (v.n_children_[i] > k || v.depth_[i] > levels) fail("bad tree (branching or depth)");
  }
  if (v.word_nodes_.size() != n_words) fail("word count does not match the tree");
  return v;
}

}  // namespace sp::loop
