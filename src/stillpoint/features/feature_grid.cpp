#include "stillpoint/features/feature_grid.hpp"

#include <algorithm>
#include <cmath>

#include "stillpoint/common/error.hpp"

namespace sp::feat {

FeatureGrid::FeatureGrid(const std::vector<cv::Point2f>& points, const std::vector<int>& octaves,
                         cv::Size image_size, float cell_size)
    : points_(points), octaves_(octaves) {
  if (points.size() != octaves.size()) throw sp::Error("FeatureGrid: points and octaves differ in length");
  if (image_size.width <= 0 || image_size.height <= 0 || !(cell_size > 0.f)) {
    throw sp::Error("FeatureGrid: image size and cell size must be positive");
  }
  inv_cell_ = 1.f / cell_size;
  cols_ = std::max(1, static_cast<int>(std::ceil(static_cast<float>(image_size.width) * inv_cell_)));
  rows_ = std::max(1, static_cast<int>(std::ceil(static_cast<float>(image_size.height) * inv_cell_)));
  // Counting sort of the points by cell.
  const auto n_cells = static_cast<std::size_t>(cols_) * static_cast<std::size_t>(rows_);
  cell_start_.assign(n_cells + 1, 0);
  std::vector<std::size_t> cell_of(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    cell_of[i] = static_cast<std::size_t>(cell_y(points[i].y) * cols_ + cell_x(points[i].x));
    ++cell_start_[cell_of[i] + 1];
  }
  for (std::size_t c = 0; c < n_cells; ++c) cell_start_[c + 1] += cell_start_[c];
  items_.resize(points.size());
  std::vector<std::size_t> fill(cell_start_.begin(), cell_start_.end() - 1);
  for (std::size_t i = 0; i < points.size(); ++i) items_[fill[cell_of[i]]++] = i;
}

int FeatureGrid::cell_x(float x) const {
  const float c = std::floor(x * inv_cell_);
  if (!(c >= 0.f)) return 0;  // also NaN
  return c >= static_cast<float>(cols_) ? cols_ - 1 : static_cast<int>(c);
}

int FeatureGrid::cell_y(float y) const {
  const float c = std::floor(y * inv_cell_);
  if (!(c >= 0.f)) return 0;
  return c >= static_cast<float>(rows_) ? rows_ - 1 : static_cast<int>(c);
}

std::vector<std::size_t> FeatureGrid::in_area(float x, float y, float radius, int min_level,
                                              int max_level) const {
  std::vector<std::size_t> out;
  in_area(x, y, radius, out, min_level, max_level);
  return out;
}

void FeatureGrid::in_area(float x, float y, float radius, std::vector<std::size_t>& out, int min_level,
                          int max_level) const {
  out.clear();
  if (points_.empty() || !(radius > 0.f)) return;
  // Clamped cell ranges also cover the points clamped into border cells.
  const int cx0 = cell_x(x - radius), cx1 = cell_x(x + radius);
  const int cy0 = cell_y(y - radius), cy1 = cell_y(y + radius);
  for (int cy = cy0; cy <= cy1; ++cy) {
    for (int cx = cx0; cx <= cx1; ++cx) {
      const auto c = static_cast<std::size_t>(cy * cols_ + cx);
      for (std::size_t k = cell_start_[c]; k < cell_start_[c + 1]; ++k) {
        const std::size_t i = items_[k];
        const int o = octaves_[i];
        if ((min_level >= 0 && o < min_level) || (max_level >= 0 && o > max_level)) continue;
        if (std::abs(points_[i].x - x) < radius && std::abs(points_[i].y - y) < radius) out.push_back(i);
      }
    }
  }
  std::sort(out.begin(), out.end());
}

}  // namespace sp::feat
