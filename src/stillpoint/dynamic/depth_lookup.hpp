#pragma once
// Depth lookups shared by the motion check's parts (internal).
#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/core.hpp>

namespace sp::dyn {

// Depth at a pixel when it is valid and its 3x3 neighbourhood agrees (no depth edge), else 0:
// points on depth edges would get the wrong 3D position and look like movers.
inline float stable_depth(const cv::Mat& depth, const cv::Point2f& p) {
  const int u = static_cast<int>(std::lround(p.x)), v = static_cast<int>(std::lround(p.y));
  if (u < 1 || v < 1 || u >= depth.cols - 1 || v >= depth.rows - 1) return 0.f;
  float lo = std::numeric_limits<float>::max(), hi = 0.f;
  for (int dv = -1; dv <= 1; ++dv) {
    const float* row = depth.ptr<float>(v + dv);
    for (int du = -1; du <= 1; ++du) {
      const float z = row[u + du];
      if (!(z > 0.f) || !std::isfinite(z)) return 0.f;
      lo = std::min(lo, z);
      hi = std::max(hi, z);
    }
  }
  const float z = depth.at<float>(v, u);
  return hi - lo < 0.02f + 0.03f * z ? z : 0.f;
}

// Depth at the nearest pixel, 0 when there is none.
inline float raw_depth(const cv::Mat* depth, const cv::Point2f& p) {
  if (depth == nullptr || depth->empty()) return 0.f;
  const int u = static_cast<int>(std::lround(p.x)), v = static_cast<int>(std::lround(p.y));
  if (u < 0 || v < 0 || u >= depth->cols || v >= depth->rows) return 0.f;
  const float z = depth->at<float>(v, u);
  return z > 0.f && std::isfinite(z) ? z : 0.f;
}

}  // namespace sp::dyn
