#pragma once
// The features of one image: what a Frame has and what a Keyframe keeps.
#include <opencv2/core.hpp>
#include <vector>

#include "stillpoint/features/feature_grid.hpp"
#include "stillpoint/geometry/camera.hpp"

namespace sp::map {

// Pyramid constants the matchers need; copied from the extractor so map data stays self-contained.
struct ScalePyramid {
  int levels = 8;
  double scale_factor = 1.2;
  std::vector<double> scale;             // scale[l] = scale_factor^l
  std::vector<double> inv_level_sigma2;  // 1 / scale[l]^2
  static ScalePyramid make(int levels, double scale_factor);
};

struct FeatureSet {
  std::vector<cv::KeyPoint> keypoints;  // undistorted positions; octave, angle as extracted
  cv::Mat descriptors;                  // N x 32, CV_8U
  std::vector<float> depth;             // metres at the keypoint, <= 0 when invalid
  std::vector<float> u_right;           // virtual stereo coordinate u - bf/depth, < 0 when invalid

  [[nodiscard]] std::size_t size() const { return keypoints.size(); }
};

// Appends `extra` to `to`, in order. The descriptors go to a new buffer, so copies of `to`'s old
// descriptors that others hold stay as they were.
void append(FeatureSet& to, const FeatureSet& extra);

// The features module's grid over a frame's keypoints, for "features near (u, v)" queries.
feat::FeatureGrid make_feature_grid(const std::vector<cv::KeyPoint>& keypoints, int width, int height);

}  // namespace sp::map
