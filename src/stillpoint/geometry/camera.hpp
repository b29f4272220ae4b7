#pragma once
// Pinhole camera with radial-tangential (OpenCV/Brown) distortion. Keypoints are undistorted once
// per frame, so everything downstream works with the ideal pinhole model.
#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <vector>

namespace sp::geo {

struct CameraIntrinsics {
  int width = 640;
  int height = 480;
  double fx = 535.4, fy = 539.2, cx = 320.1, cy = 247.6;  // TUM fr3 defaults
  double k1 = 0, k2 = 0, p1 = 0, p2 = 0, k3 = 0;

  [[nodiscard]] bool has_distortion() const { return k1 != 0 || k2 != 0 || p1 != 0 || p2 != 0 || k3 != 0; }
  [[nodiscard]] cv::Mat K() const;            // 3x3 CV_64F
  [[nodiscard]] cv::Mat dist_coeffs() const;  // 1x5 CV_64F (k1 k2 p1 p2 k3)

  // Ideal pinhole projection of a point in the camera frame (z > 0 is the caller's check).
  [[nodiscard]] Eigen::Vector2d project(const Eigen::Vector3d& p_c) const {
    return {fx * p_c.x() / p_c.z() + cx, fy * p_c.y() / p_c.z() + cy};
  }
  // Back-projection of an undistorted pixel at depth z (the camera-frame z, not the ray length).
  [[nodiscard]] Eigen::Vector3d unproject(const Eigen::Vector2d& uv, double z) const {
    return {(uv.x() - cx) * z / fx, (uv.y() - cy) * z / fy, z};
  }
  [[nodiscard]] bool in_image(const Eigen::Vector2d& uv, double border = 0.0) const {
    return uv.x() >= border && uv.y() >= border && uv.x() < width - border && uv.y() < height - border;
  }
  // Removes lens distortion from pixel coordinates (identity when there is none).
  [[nodiscard]] std::vector<cv::Point2f> undistort(const std::vector<cv::Point2f>& pixels) const;
  // Applies lens distortion to an ideal pixel (for drawing / simulation).
  [[nodiscard]] Eigen::Vector2d distort(const Eigen::Vector2d& ideal) const;
};

}  // namespace sp::geo
