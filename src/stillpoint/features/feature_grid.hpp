#pragma once
// A uniform grid over the keypoints of one frame for fast window queries (ORB-SLAM's
// GetFeaturesInArea). Points outside the image are clamped into the border cells, so none is lost.
#include <cstddef>
#include <opencv2/core/types.hpp>
#include <vector>

namespace sp::feat {

class FeatureGrid {
 public:
  FeatureGrid() = default;
  // points: undistorted keypoint positions [px]; octaves: pyramid level of each (same length);
  // cell_size: grid cell side [px] (ORB-SLAM uses 640/64 = 10).
  FeatureGrid(const std::vector<cv::Point2f>& points, const std::vector<int>& octaves, cv::Size image_size,
              float cell_size = 10.f);

  // Indices (ascending) of the points with |px - x| < radius and |py - y| < radius, and, when the
  // bound is >= 0, octave >= min_level and octave <= max_level.
  [[nodiscard]] std::vector<std::size_t> in_area(float x, float y, float radius, int min_level = -1,
                                                 int max_level = -1) const;
  // Same, appending to `out` (cleared first) to avoid an allocation per query.
  void in_area(float x, float y, float radius, std::vector<std::size_t>& out, int min_level = -1,
               int max_level = -1) const;

  [[nodiscard]] std::size_t size() const noexcept { return points_.size(); }
  [[nodiscard]] const cv::Point2f& point(std::size_t i) const { return points_[i]; }
  [[nodiscard]] int octave(std::size_t i) const { return octaves_[i]; }
  [[nodiscard]] int cols() const noexcept { return cols_; }
  [[nodiscard]] int rows() const noexcept { return rows_; }

 private:
  [[nodiscard]] int cell_x(float x) const;
  [[nodiscard]] int cell_y(float y) const;

  std::vector<cv::Point2f> points_;
  std::vector<int> octaves_;
  float inv_cell_ = 0.1f;
  int cols_ = 0, rows_ = 0;
  std::vector<std::size_t> cell_start_;  // CSR layout: items of cell c are [start[c], start[c+1])
  std::vector<std::size_t> items_;
};

}  // namespace sp::feat
