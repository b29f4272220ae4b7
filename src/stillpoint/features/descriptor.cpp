#include "stillpoint/features/descriptor.hpp"

#include <algorithm>

#include "stillpoint/common/error.hpp"

namespace sp::feat {

int distinctive_descriptor_index(const std::vector<const std::uint8_t*>& descs) {
  const std::size_t n = descs.size();
  if (n == 0) return -1;
  std::vector<int> dist(n * n, 0);
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = i + 1; j < n; ++j)
      dist[i * n + j] = dist[j * n + i] = hamming_distance(descs[i], descs[j]);
  }
  int best = 0, best_median = 257;
  std::vector<int> row(n);
  for (std::size_t i = 0; i < n; ++i) {
    row.assign(dist.begin() + static_cast<std::ptrdiff_t>(i * n),
               dist.begin() + static_cast<std::ptrdiff_t>((i + 1) * n));
    // Lower median of the distances to all (including itself, as ORB-SLAM).
    std::nth_element(row.begin(), row.begin() + static_cast<std::ptrdiff_t>((n - 1) / 2), row.end());
    const int median = row[(n - 1) / 2];
    if (median < best_median) {
      best_median = median;
      best = static_cast<int>(i);
    }
  }
  return best;
}

int hamming_distance(const cv::Mat& a_row, const cv::Mat& b_row) {
  const auto ok = [](const cv::Mat& m) {
    return m.type() == CV_8UC1 && m.rows == 1 && m.cols == kDescriptorBytes;
  };
  if (!ok(a_row) || !ok(b_row)) throw sp::Error("hamming_distance: descriptors must be 1 x 32 CV_8U rows");
  return hamming_distance(a_row.ptr<std::uint8_t>(), b_row.ptr<std::uint8_t>());
}

}  // namespace sp::feat
