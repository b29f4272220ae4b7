#include "stillpoint/tracking/frame.hpp"

#include <cmath>

namespace sp::track {

int Frame::matched() const {
  int n = 0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (points[i] != map::kNoPoint && !outlier[i]) ++n;
  }
  return n;
}

void attach_depth(map::FeatureSet& features, const std::vector<cv::KeyPoint>& keypoints_distorted,
                  const cv::Mat& depth, const DepthModel& model) {
  const std::size_t n = features.keypoints.size();
  features.depth.assign(n, -1.0f);
  features.u_right.assign(n, -1.0f);
  if (depth.empty()) return;
  for (std::size_t i = 0; i < n; ++i) {
    const auto u = static_cast<int>(std::lround(keypoints_distorted[i].pt.x));
    const auto v = static_cast<int>(std::lround(keypoints_distorted[i].pt.y));
    if (u < 0 || v < 0 || u >= depth.cols || v >= depth.rows) continue;
    const float d = depth.at<float>(v, u);
    if (!(d > model.depth_min && d < model.depth_max)) continue;
    features.depth[i] = d;
    features.u_right[i] = static_cast<float>(features.keypoints[i].pt.x - model.bf / d);
  }
}

std::vector<cv::KeyPoint> undistort_keypoints(const std::vector<cv::KeyPoint>& keypoints,
                                              const geo::CameraIntrinsics& camera) {
  if (!camera.has_distortion()) return keypoints;
  std::vector<cv::Point2f> pts;
  pts.reserve(keypoints.size());
  for (const auto& kp : keypoints) pts.push_back(kp.pt);
  const auto und = camera.undistort(pts);
  std::vector<cv::KeyPoint> out = keypoints;
  for (std::size_t i = 0; i < out.size(); ++i) out[i].pt = und[i];
  return out;
}

}  // namespace sp::track
