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

feat::FeatureGrid make_feature_grid(const std::vector<cv::KeyPoint>& keypoints, int width, int height) {
  std::vector<cv::Point2f> points;
  std::vector<int> octaves;
  points.reserve(keypoints.size());
  octaves.reserve(keypoints.size());
  for (const auto& kp : keypoints) {
    points.push_back(kp.pt);
    octaves.push_back(kp.octave);
  }
  return feat::FeatureGrid(points, octaves, cv::Size(width, height));
}

}  // namespace sp::map
