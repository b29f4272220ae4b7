#include "stillpoint/map/feature_set.hpp"

#include <algorithm>
#include <cmath>

namespace sp::map {

ScalePyramid ScalePyramid::make(int levels, double scale_factor) {
  ScalePyramid p;
  p.levels = levels;
  p.scale_factor = scale_factor;
  double s = 1.0;
  for (int l = 0; l < levels; ++l) {
    p.scale.push_back(s);
    p.inv_level_sigma2.push_back(1.0 / (s * s));
    s *= scale_factor;
  }
  return p;
}

FeatureIndex::FeatureIndex(const std::vector<cv::KeyPoint>& keypoints, int width, int height)
    : cols_(std::max(1, (width + kCell - 1) / kCell)),
      rows_(std::max(1, (height + kCell - 1) / kCell)),
      cells_(static_cast<std::size_t>(cols_ * rows_)) {
  points_.reserve(keypoints.size());
  levels_.reserve(keypoints.size());
  for (std::size_t i = 0; i < keypoints.size(); ++i) {
    points_.push_back(keypoints[i].pt);
    levels_.push_back(keypoints[i].octave);
    const int cx = std::clamp(static_cast<int>(keypoints[i].pt.x / kCell), 0, cols_ - 1);
    const int cy = std::clamp(static_cast<int>(keypoints[i].pt.y / kCell), 0, rows_ - 1);
    cells_[static_cast<std::size_t>(cy * cols_ + cx)].push_back(static_cast<int>(i));
  }
}

std::vector<int> FeatureIndex::in_area(double u, double v, double radius, int min_level,
                                       int max_level) const {
  std::vector<int> out;
  if (cells_.empty()) return out;
  const int x0 = std::max(0, static_cast<int>(std::floor((u - radius) / kCell)));
  const int x1 = std::min(cols_ - 1, static_cast<int>(std::floor((u + radius) / kCell)));
  const int y0 = std::max(0, static_cast<int>(std::floor((v - radius) / kCell)));
  const int y1 = std::min(rows_ - 1, static_cast<int>(std::floor((v + radius) / kCell)));
  for (int y = y0; y <= y1; ++y) {
    for (int x = x0; x <= x1; ++x) {
      for (int i : cells_[static_cast<std::size_t>(y * cols_ + x)]) {
        const auto idx = static_cast<std::size_t>(i);
        if (min_level >= 0 && levels_[idx] < min_level) continue;
        if (max_level >= 0 && levels_[idx] > max_level) continue;
        if (std::abs(points_[idx].x - u) < radius && std::abs(points_[idx].y - v) < radius) out.push_back(i);
      }
    }
  }
  return out;
}

}  // namespace sp::map
