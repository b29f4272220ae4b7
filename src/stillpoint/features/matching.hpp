#pragma once
// Descriptor matching helpers: brute-force ratio-test matching and ORB-SLAM's rotation-consistency
// histogram.
#include <cstddef>
#include <opencv2/core/mat.hpp>
#include <vector>

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
