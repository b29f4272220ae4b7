#pragma once
// Descriptor matching helpers: brute-force ratio-test matching and ORB-SLAM's rotation-consistency
// histogram.
#include <cstddef>
#include <opencv2/core/mat.hpp>
#include <vector>

#include "stillpoint/features/descriptor.hpp"
#include "stillpoint/features/feature_grid.hpp"

namespace sp::feat {

// Descriptor distance thresholds typical of ORB-SLAM (bits out of 256).
constexpr int kThHigh = 100;
constexpr int kThLow = 50;

struct DescriptorMatch {
  int query;     // row in the query descriptors
  int train;     // row in the train descriptors
  int distance;  // Hamming distance [bits]
};

// For each query row, the nearest train row by Hamming distance, kept when distance <= max_distance
// and distance < ratio * second-nearest distance (Lowe). With cross_check, also require that the
// query row is the nearest of all query rows to that train row. Ties go to the lower index.
// Descriptors: N x 32 CV_8U (either may be empty). Sorted by query index.
std::vector<DescriptorMatch> match_ratio(const cv::Mat& query, const cv::Mat& train, float ratio = 0.8f,
                                         int max_distance = 64, bool cross_check = false);

// Result of a guided search around a predicted position (ORB-SLAM's search by projection).
struct AreaMatch {
  static constexpr int kNone = 257;  // distance when there is no such feature
  int index = -1;                    // best feature, -1 when none
  int distance = kNone;              // its Hamming distance [bits]
  int level = -1;                    // its octave
  int second_distance = kNone;       // the runner-up's distance [bits]
  int second_level = -1;             // the runner-up's octave
};

// Best and second-best descriptor among the grid's features in the square window of `radius`
// around (x, y) with octave in [min_level, max_level] (bounds < 0: unbounded), skipping the
// indices for which skip(index) is true (e.g. already matched). `descriptors`: rows of the frame
// the grid was built from; `scratch` avoids an allocation per call.
template <typename Skip>
AreaMatch best_in_area(const FeatureGrid& grid, const cv::Mat& descriptors, const std::uint8_t* query,
                       float x, float y, float radius, int min_level, int max_level,
                       std::vector<std::size_t>& scratch, Skip&& skip) {
  AreaMatch m;
  grid.in_area(x, y, radius, scratch, min_level, max_level);
  for (std::size_t i : scratch) {
    if (skip(i)) continue;
    const int d = hamming_distance(query, descriptors.ptr<std::uint8_t>(static_cast<int>(i)));
    if (d < m.distance) {
      m.second_distance = m.distance;
      m.second_level = m.level;
      m.distance = d;
      m.level = grid.octave(i);
      m.index = static_cast<int>(i);
    } else if (d < m.second_distance) {
      m.second_distance = d;
      m.second_level = grid.octave(i);
    }
  }
  return m;
}

// Histogram of keypoint angle differences of matches: matches whose rotation disagrees with the
// dominant ones are outliers.
class RotationHistogram {
 public:
  explicit RotationHistogram(int bins = 30);

  // angle_diff_deg: e.g. angle(query) - angle(train), any range; index: the caller's match id.
  void add(float angle_diff_deg, std::size_t index);
  // Indices (ascending) outside the three most populated bins; the 2nd and 3rd bins only count
  // as inliers when they hold at least 10 % of the largest.
  [[nodiscard]] std::vector<std::size_t> outliers() const;
  [[nodiscard]] std::vector<std::size_t> inliers() const;
  [[nodiscard]] int bins() const noexcept { return static_cast<int>(bins_.size()); }
  void clear();

 private:
  [[nodiscard]] std::vector<bool> kept_bins() const;
  std::vector<std::vector<std::size_t>> bins_;
};

}  // namespace sp::feat
