#include "stillpoint/geometry/camera.hpp"

#include <opencv2/calib3d.hpp>

namespace sp::geo {

cv::Mat CameraIntrinsics::K() const { return (cv::Mat_<double>(3, 3) << fx, 0, cx, 0, fy, cy, 0, 0, 1); }

cv::Mat CameraIntrinsics::dist_coeffs() const { return (cv::Mat_<double>(1, 5) << k1, k2, p1, p2, k3); }

std::vector<cv::Point2f> CameraIntrinsics::undistort(const std::vector<cv::Point2f>& pixels) const {
  if (!has_distortion() || pixels.empty()) return pixels;
  std::vector<cv::Point2f> out;
  // P = K maps the normalised result back to pixels of the ideal camera.
  cv::undistortPoints(pixels, out, K(), dist_coeffs(), cv::noArray(), K());
  return out;
}

Eigen::Vector2d CameraIntrinsics::distort(const Eigen::Vector2d& ideal) const {
  const double x = (ideal.x() - cx) / fx;
  const double y = (ideal.y() - cy) / fy;
  const double r2 = x * x + y * y;
  const double radial = 1 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2;
  const double xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x);
  const double yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y;
  return {fx * xd + cx, fy * yd + cy};
}

}  // namespace sp::geo
