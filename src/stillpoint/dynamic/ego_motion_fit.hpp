#pragma once
// Robust fit of the camera's own motion between two frames from tracked points, for the motion check.
#include <opencv2/core.hpp>
#include <optional>
#include <vector>

namespace sp::dyn {

// Correspondences of one frame step. Points with depth: 3-D in the current camera and their observed
// pixel in the previous image. Points without depth (beyond the sensor's range): pixel pairs.
struct MotionFitPoints {
  std::vector<cv::Point3f> cur_3d;
  std::vector<cv::Point2f> prev_px;
  std::vector<cv::Point2f> flat_cur_px, flat_prev_px;
};

struct MsacOptions {
  double threshold_px = 1.0;       // squared reprojection residual truncated here
  double flat_threshold_px = 1.0;  // squared epipolar distance of the flat points truncated here
  int iterations = 200;            // minimal-sample hypotheses
};

struct CameraMotion {  // maps current-camera points into the previous camera: x_prev = R x_cur + t
  cv::Matx33d R = cv::Matx33d::eye();
  cv::Vec3d t{0, 0, 0};
  int inliers = 0;  // points with depth within threshold_px
};

// MSAC: hypotheses from random triples of points with depth (Gauss-Newton on their reprojection from
// `guess`, or from no motion: frame-to-frame motion is small), plus `guess` itself, scored by the
// truncated squared residual of every point (flat points by their epipolar distance, or the rotation
// homography's transfer error when the camera barely translates); the best is refined by least
// squares on its inliers, then on those of the refined motion within max(1 px, half the threshold). Counting
// inliers cannot tell a close person walking slowly (fitted within the threshold by a slightly wrong motion)
// from the background; the size of the residuals can. Deterministic: a fixed seed per call. nullopt: fewer
// than 4 points with depth, or no hypothesis.
std::optional<CameraMotion> fit_camera_motion_msac(const MotionFitPoints& pts, const cv::Matx33d& K,
                                                   const std::optional<CameraMotion>& guess,
                                                   const MsacOptions& opt);

// Distance (px) of `x` to the epipolar line F * y; -1 when the line is undefined.
float epipolar_line_distance(const cv::Matx33d& F, const cv::Point2f& y, const cv::Point2f& x);
// Distance (px) of H * y to x; -1 when H maps y to infinity.
float homography_transfer_error(const cv::Matx33d& H, const cv::Point2f& y, const cv::Point2f& x);

}  // namespace sp::dyn
