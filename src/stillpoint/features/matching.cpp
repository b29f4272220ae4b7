#include "stillpoint/features/matching.hpp"

#include <algorithm>
#include <climits>
#include <cmath>

#include "stillpoint/common/error.hpp"
#include "stillpoint/features/descriptor.hpp"

namespace sp::feat {

std::vector<DescriptorMatch> match_ratio(const cv::Mat& query, const cv::Mat& train, float ratio,
                                         int max_distance, bool cross_check) {
  const auto check = [](const cv::Mat& m, const char* name) {
    if (!m.empty() && (m.type() != CV_8UC1 || m.cols != kDescriptorBytes)) {
      throw sp::Error(std::string("match_ratio: ") + name + " descriptors must be N x 32 CV_8U");
    }
  };
  check(query, "query");
  check(train, "train");
  std::vector<DescriptorMatch> out;
  if (query.empty() || train.empty()) return out;

  // Nearest query of each train row, for the cross check.
  std::vector<int> train_best(cross_check ? static_cast<std::size_t>(train.rows) : 0, INT_MAX);
  std::vector<int> train_best_q(train_best.size(), -1);
  for (int q = 0; q < query.rows; ++q) {
    const std::uint8_t* qd = query.ptr<std::uint8_t>(q);
    int best = INT_MAX, second = INT_MAX, best_t = -1;
    for (int t = 0; t < train.rows; ++t) {
      const int d = hamming_distance(qd, train.ptr<std::uint8_t>(t));
      if (d < best) {
        second = best;
        best = d;
        best_t = t;
      } else if (d < second) {
        second = d;
      }
      if (cross_check && d < train_best[static_cast<std::size_t>(t)]) {
        train_best[static_cast<std::size_t>(t)] = d;
        train_best_q[static_cast<std::size_t>(t)] = q;
      }
    }
    if (best > max_distance) continue;
    if (second != INT_MAX && !(static_cast<float>(best) < ratio * static_cast<float>(second))) continue;
    out.push_back({q, best_t, best});
  }
  if (cross_check) {
    std::erase_if(out, [&](const DescriptorMatch& m) {
      return train_best_q[static_cast<std::size_t>(m.train)] != m.query;
    });
  }
  return out;
}

RotationHistogram::RotationHistogram(int bins) {
  if (bins < 3) throw sp::Error("RotationHistogram: needs at least 3 bins");
  bins_.resize(static_cast<std::size_t>(bins));
}

void RotationHistogram::add(float angle_diff_deg, std::size_t index) {
  double a = std::fmod(static_cast<double>(angle_diff_deg), 360.0);
  if (a < 0) a += 360.0;
  const int n = bins();
  // Bins centred on multiples of 360/n, so small differences of either sign share bin 0.
  int b = static_cast<int>(std::lround(a * n / 360.0));
  if (b >= n) b = 0;
  bins_[static_cast<std::size_t>(b)].push_back(index);
}

void RotationHistogram::clear() {
  for (auto& b : bins_) b.clear();
}

std::vector<bool> RotationHistogram::kept_bins() const {
  // The three largest bins; ties go to the lower bin.
  int i1 = -1, i2 = -1, i3 = -1;
  std::size_t m1 = 0, m2 = 0, m3 = 0;
  for (int i = 0; i < bins(); ++i) {
    const std::size_t s = bins_[static_cast<std::size_t>(i)].size();
    if (s > m1) {
      m3 = m2, i3 = i2, m2 = m1, i2 = i1, m1 = s, i1 = i;
    } else if (s > m2) {
      m3 = m2, i3 = i2, m2 = s, i2 = i;
    } else if (s > m3) {
      m3 = s, i3 = i;
    }
  }
  if (static_cast<double>(m2) < 0.1 * static_cast<double>(m1)) {
    i2 = i3 = -1;
  } else if (static_cast<double>(m3) < 0.1 * static_cast<double>(m1)) {
    i3 = -1;
  }
  std::vector<bool> kept(bins_.size(), false);
  for (int i : {i1, i2, i3}) {
    if (i >= 0) kept[static_cast<std::size_t>(i)] = true;
  }
  return kept;
}

std::vector<std::size_t> RotationHistogram::outliers() const {
  const std::vector<bool> kept = kept_bins();
  std::vector<std::size_t> out;
  for (std::size_t b = 0; b < bins_.size(); ++b) {
    if (!kept[b]) out.insert(out.end(), bins_[b].begin(), bins_[b].end());
  }
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<std::size_t> RotationHistogram::inliers() const {
  const std::vector<bool> kept = kept_bins();
  std::vector<std::size_t> out;
  for (std::size_t b = 0; b < bins_.size(); ++b) {
    if (kept[b]) out.insert(out.end(), bins_[b].begin(), bins_[b].end());
  }
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace sp::feat
