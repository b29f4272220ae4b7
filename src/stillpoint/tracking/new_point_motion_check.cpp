#include "stillpoint/tracking/new_point_motion_check.hpp"

#include <algorithm>
#include <opencv2/video/tracking.hpp>

#include "stillpoint/common/error.hpp"

namespace sp::track {

NewPointMotionCheckConfig NewPointMotionCheckConfig::from_yaml(const ConfigReader& r) {
  NewPointMotionCheckConfig c;
  r.read("max_residual_px", c.max_residual_px, 0.0, 100.0);
  r.read("fb_max_px", c.fb_max_px, 0.01, 10.0);
  r.read("lk_window", c.lk_window, 3, 63);
  r.read("lk_levels", c.lk_levels, 0, 8);
  return c;
}

NewPointMotionCheck::NewPointMotionCheck(const NewPointMotionCheckConfig& config,
                                         const geo::CameraIntrinsics& camera)
    : config_(config), camera_(camera) {}

std::vector<bool> NewPointMotionCheck::static_candidates(const cv::Mat& prev_gray, const cv::Mat& cur_gray,
                                                         const geo::SE3& T_prev_cur,
                                                         const std::vector<Eigen::Vector2d>& ideal_px,
                                                         const std::vector<double>& depth) const {
  if (ideal_px.size() != depth.size()) throw Error("new point motion check: pixel and depth counts differ");
  std::vector<bool> ok(ideal_px.size(), true);
  if (!config_.enabled() || ideal_px.empty() || prev_gray.empty() || cur_gray.empty() ||
      prev_gray.size() != cur_gray.size())
    return ok;
  // Where each candidate should be in the previous image if it is static; candidates that leave the
  // previous view cannot be checked.
  std::vector<cv::Point2f> cur, predicted;
  std::vector<std::size_t> which;
  for (std::size_t i = 0; i < ideal_px.size(); ++i) {
    if (depth[i] <= 0) continue;
    const Eigen::Vector3d p_prev = T_prev_cur * camera_.unproject(ideal_px[i], depth[i]);
    if (p_prev.z() <= 0) continue;
    const Eigen::Vector2d uv_prev = camera_.distort(camera_.project(p_prev));
    if (!camera_.in_image(uv_prev, 1.0)) continue;
    const Eigen::Vector2d uv_cur = camera_.distort(ideal_px[i]);
    cur.emplace_back(static_cast<float>(uv_cur.x()), static_cast<float>(uv_cur.y()));
    predicted.emplace_back(static_cast<float>(uv_prev.x()), static_cast<float>(uv_prev.y()));
    which.push_back(i);
  }
  if (cur.empty()) return ok;
  // Flow from the current image back to the previous one, started at the static prediction, checked
  // by flowing forward again.
  // Each image's pyramid is built once and serves both directions.
  const cv::Size win(config_.lk_window, config_.lk_window);
  const cv::TermCriteria term(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 20, 0.03);
  std::vector<cv::Mat> pyr_cur, pyr_prev;
  const int levels_cur = cv::buildOpticalFlowPyramid(cur_gray, pyr_cur, win, config_.lk_levels);
  const int levels_prev = cv::buildOpticalFlowPyramid(prev_gray, pyr_prev, win, config_.lk_levels);
  const int levels = std::min(levels_cur, levels_prev);
  std::vector<cv::Point2f> back = predicted, fwd = cur;
  std::vector<uchar> st_back, st_fwd;
  std::vector<float> err;
  cv::calcOpticalFlowPyrLK(pyr_cur, pyr_prev, cur, back, st_back, err, win, levels, term,
                           cv::OPTFLOW_USE_INITIAL_FLOW);
  cv::calcOpticalFlowPyrLK(pyr_prev, pyr_cur, back, fwd, st_fwd, err, win, levels, term,
                           cv::OPTFLOW_USE_INITIAL_FLOW);
  const double fb2 = config_.fb_max_px * config_.fb_max_px;
  const double max2 = config_.max_residual_px * config_.max_residual_px;
  for (std::size_t k = 0; k < cur.size(); ++k) {
    if (!st_back[k] || !st_fwd[k]) continue;
    const cv::Point2f fb = fwd[k] - cur[k];
    if (fb.dot(fb) > fb2) continue;
    const cv::Point2f r = back[k] - predicted[k];
    if (r.dot(r) > max2) ok[which[k]] = false;
  }
  return ok;
}

}  // namespace sp::track
