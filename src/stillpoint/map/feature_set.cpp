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

void append(FeatureSet& to, const FeatureSet& extra) {
  to.keypoints.insert(to.keypoints.end(), extra.keypoints.begin(), extra.keypoints.end());
  to.depth.insert(to.depth.end(), extra.depth.begin(), extra.depth.end());
  to.u_right.insert(to.u_right.end(), extra.u_right.begin(), extra.u_right.end());
  cv::Mat descriptors;
  if (to.descriptors.empty()) {
    descriptors = extra.descriptors.clone();
  } else {
    cv::vconcat(to.descriptors, extra.descriptors, descriptors);
  }
  to.descriptors = descriptors;
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
