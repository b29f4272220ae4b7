// Ego-motion compensation of the motion check: the residual of each tracked point after the
// camera's own motion is explained (reprojection with depth, else epipolar / homography).
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include "stillpoint/dynamic/depth_lookup.hpp"
#include "stillpoint/dynamic/dynamic_filter.hpp"

namespace sp::dyn {

namespace {

// Distance of `x` to the epipolar line F * y (pixels); F maps points y to lines in x's image.
float line_distance(const cv::Matx33d& F, const cv::Point2f& y, const cv::Point2f& x) {
  const cv::Vec3d l = F * cv::Vec3d(y.x, y.y, 1.0);
  const double n = std::hypot(l[0], l[1]);
  return n > 1e-12 ? static_cast<float>(std::abs(l[0] * x.x + l[1] * x.y + l[2]) / n) : -1.f;
}

float transfer_error(const cv::Matx33d& H, const cv::Point2f& y, const cv::Point2f& x) {
  const cv::Vec3d q = H * cv::Vec3d(y.x, y.y, 1.0);
  if (std::abs(q[2]) < 1e-12) return -1.f;
  return static_cast<float>(std::hypot(q[0] / q[2] - x.x, q[1] / q[2] - x.y));
}

cv::Matx33d skew(const cv::Vec3d& t) { return {0, -t[2], t[1], t[2], 0, -t[0], -t[1], t[0], 0}; }

}  // namespace

bool DynamicFeatureFilter::reprojection_residuals(const DynamicInput& in, const std::vector<int>& fit,
                                                  DynamicResult& res, std::vector<float>& eps) const {
  const auto& cur = res.flow_points;
  const auto& prev = res.flow_prev;
  const std::size_t n = cur.size();
  const Eigen::Matrix3d& K = *in.K;
  const double fx = K(0, 0), fy = K(1, 1), cx = K(0, 2), cy = K(1, 2);
  std::vector<cv::Point3f> X(n);
  std::vector<bool> has_z(n, false);
  for (std::size_t i = 0; i < n; ++i) {
    const float z = stable_depth(*in.depth, cur[i]);
    if (z <= 0.f) continue;
    has_z[i] = true;
    X[i] = cv::Point3f(static_cast<float>((cur[i].x - cx) * z / fx),
                       static_cast<float>((cur[i].y - cy) * z / fy), z);
  }
  std::vector<cv::Point3f> obj;
  std::vector<cv::Point2f> img;
  for (int i : fit) {
    if (!has_z[static_cast<std::size_t>(i)]) continue;
    obj.push_back(X[static_cast<std::size_t>(i)]);
    img.push_back(prev[static_cast<std::size_t>(i)]);
  }
  cv::Mat Kcv;
  cv::eigen2cv(K, Kcv);
  // The camera motion maps current-frame points into the previous camera: T_prev_cur.
  cv::Mat rvec = cv::Mat::zeros(3, 1, CV_64F), tvec = cv::Mat::zeros(3, 1, CV_64F);
  bool guess = false;
  if (in.T_cur_prev_predicted) {
    const Eigen::Isometry3d T = in.T_cur_prev_predicted->inverse();
    const Eigen::Matrix3d R = T.linear();
    cv::Mat Rcv;
    cv::eigen2cv(R, Rcv);
    cv::Rodrigues(Rcv, rvec);
    for (int k = 0; k < 3; ++k) tvec.at<double>(k) = T.translation()(k);
    guess = true;
  }
  bool ok = false;
  if (obj.size() >= 8) {
    std::vector<int> inliers;
    ok = cv::solvePnPRansac(obj, img, Kcv, cv::noArray(), rvec, tvec, guess, cfg_.ransac_iterations,
                            static_cast<float>(cfg_.epsilon_reprojection_px), cfg_.ransac_confidence, inliers,
                            cv::SOLVEPNP_ITERATIVE);
    ok = ok && static_cast<double>(inliers.size()) >= std::max(6.0, 0.3 * static_cast<double>(obj.size()));
    res.ego_inliers = ok ? static_cast<int>(inliers.size()) : 0;
    if (!ok && guess) {  // keep the prediction, not what a failed RANSAC left behind
      const Eigen::Isometry3d T = in.T_cur_prev_predicted->inverse();
      cv::Mat Rcv;
      cv::eigen2cv(Eigen::Matrix3d(T.linear()), Rcv);
      cv::Rodrigues(Rcv, rvec);
      for (int k = 0; k < 3; ++k) tvec.at<double>(k) = T.translation()(k);
    }
  }
  if (!ok && !guess) return false;

  cv::Mat Rm;
  cv::Rodrigues(rvec, Rm);
  const cv::Matx33d R(Rm);
  const cv::Vec3d t(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2));
  const cv::Matx33d Kx(Kcv), Ki = Kx.inv();
  // Points without usable depth: epipolar distance from the same motion, or the rotation
  // homography when the camera barely translated (the epipolar geometry is degenerate then).
  const bool translating = cv::norm(t) > 1e-3;
  const cv::Matx33d F = Ki.t() * skew(t) * R * Ki;
  const cv::Matx33d H = Kx * R * Ki;
  for (std::size_t i = 0; i < n; ++i) {
    if (has_z[i]) {
      const cv::Vec3d q = R * cv::Vec3d(X[i].x, X[i].y, X[i].z) + t;
      if (q[2] <= 1e-6) continue;
      const double u = fx * q[0] / q[2] + cx, v = fy * q[1] / q[2] + cy;
      res.flow_residual[i] = static_cast<float>(std::hypot(u - prev[i].x, v - prev[i].y));
      eps[i] = static_cast<float>(cfg_.epsilon_reprojection_px);
    } else {
      res.flow_residual[i] =
          translating ? line_distance(F, cur[i], prev[i]) : transfer_error(H, cur[i], prev[i]);
      eps[i] = static_cast<float>(cfg_.epsilon_epipolar_px);
    }
  }
  res.residual_used = "reprojection";
  return true;
}

void DynamicFeatureFilter::epipolar_residuals(const std::vector<int>& fit, DynamicResult& res,
                                              std::vector<float>& eps) const {
  const auto& cur = res.flow_points;
  const auto& prev = res.flow_prev;
  std::vector<cv::Point2f> p, c;
  for (int i : fit) {
    p.push_back(prev[static_cast<std::size_t>(i)]);
    c.push_back(cur[static_cast<std::size_t>(i)]);
  }
  if (p.size() < 8) return;
  const double thr = cfg_.ransac_threshold_px;
  cv::Mat mask_h, mask_f;
  const cv::Mat H =
      cv::findHomography(p, c, cv::RANSAC, thr, mask_h, cfg_.ransac_iterations * 10, cfg_.ransac_confidence);
  const cv::Mat F = cv::findFundamentalMat(p, c, cv::FM_RANSAC, thr, cfg_.ransac_confidence, mask_f);
  const int h_in = H.empty() ? 0 : cv::countNonZero(mask_h);
  const int f_in = F.rows == 3 && F.cols == 3 ? cv::countNonZero(mask_f) : 0;
  // Parallax evidence: points the fundamental matrix explains but the homography does not. Without
  // it the epipolar geometry is degenerate (static / rotating camera, planar scene) and RANSAC would
  // pick an F that also explains a moving object, so the homography residual is used instead.
  int parallax = 0;
  if (h_in > 0 && f_in > 0) {
    for (int i = 0; i < mask_f.rows * mask_f.cols; ++i) parallax += mask_f.data[i] && !mask_h.data[i] ? 1 : 0;
  }
  const int min_parallax = std::max(8, static_cast<int>(0.05 * static_cast<double>(p.size())));
  const bool use_h = h_in > 0 && (f_in == 0 || parallax < min_parallax);
  if (!use_h && f_in == 0) return;
  const cv::Matx33d M(use_h ? H : F(cv::Rect(0, 0, 3, 3)));
  for (std::size_t i = 0; i < cur.size(); ++i) {
    res.flow_residual[i] = use_h ? transfer_error(M, prev[i], cur[i]) : line_distance(M, prev[i], cur[i]);
    eps[i] = static_cast<float>(cfg_.epsilon_epipolar_px);
  }
  res.residual_used = use_h ? "homography" : "epipolar";
  res.ego_inliers = use_h ? h_in : f_in;
}

}  // namespace sp::dyn
