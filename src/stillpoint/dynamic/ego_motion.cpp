// Ego-motion compensation of the motion check: the residual of each tracked point after the
// camera's own motion is explained (reprojection with depth, else epipolar / homography).
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <opencv2/video/tracking.hpp>

#include "stillpoint/dynamic/depth_lookup.hpp"
#include "stillpoint/dynamic/dynamic_filter.hpp"
#include "stillpoint/dynamic/ego_motion_fit.hpp"

namespace sp::dyn {

namespace {

cv::Matx33d skew(const cv::Vec3d& t) { return {0, -t[2], t[1], t[2], 0, -t[0], -t[1], t[0], 0}; }

// Squared reprojection residuals of the points with depth under (R, t).
void squared_residuals(const MotionFitPoints& pts, const cv::Matx33d& K, const cv::Matx33d& R,
                       const cv::Vec3d& t, std::vector<double>& r2) {
  r2.resize(pts.cur_3d.size());
  for (std::size_t i = 0; i < pts.cur_3d.size(); ++i) {
    const cv::Point3f& X = pts.cur_3d[i];
    const cv::Vec3d q = R * cv::Vec3d(X.x, X.y, X.z) + t;
    if (q[2] <= 1e-6) {
      r2[i] = std::numeric_limits<double>::max();
      continue;
    }
    const double du = K(0, 0) * q[0] / q[2] + K(0, 2) - pts.prev_px[i].x;
    const double dv = K(1, 1) * q[1] / q[2] + K(1, 2) - pts.prev_px[i].y;
    r2[i] = du * du + dv * dv;
  }
}

double truncated_sum(const std::vector<double>& r2, double thr2) {
  double c = 0.0;
  for (double v : r2) c += std::min(v, thr2);
  return c;
}

// Residual of a point without depth under the camera motion (R, t): its epipolar distance, or the
// rotation homography's transfer error when the camera barely translates (the epipolar geometry is
// degenerate then). Shared by the MSAC score and the per-point verdict.
class DepthlessResidual {
 public:
  DepthlessResidual(const cv::Matx33d& K, const cv::Matx33d& Ki, const cv::Matx33d& R, const cv::Vec3d& t)
      : translating_(cv::norm(t) > 1e-3), M_(translating_ ? Ki.t() * skew(t) * R * Ki : K * R * Ki) {}
  // px, negative when undefined; `cur` in the current image, `prev` its match in the previous one.
  [[nodiscard]] float operator()(const cv::Point2f& cur, const cv::Point2f& prev) const {
    return translating_ ? epipolar_line_distance(M_, cur, prev) : homography_transfer_error(M_, cur, prev);
  }

 private:
  bool translating_;
  cv::Matx33d M_;
};

// Truncated squared residual of the points without depth.
double flat_cost(const MotionFitPoints& pts, const cv::Matx33d& K, const cv::Matx33d& Ki,
                 const cv::Matx33d& R, const cv::Vec3d& t, double thr) {
  if (pts.flat_cur_px.empty()) return 0.0;
  const DepthlessResidual residual(K, Ki, R, t);
  const double thr2 = thr * thr;
  double c = 0.0;
  for (std::size_t i = 0; i < pts.flat_cur_px.size(); ++i) {
    const double d = residual(pts.flat_cur_px[i], pts.flat_prev_px[i]);
    c += d < 0.0 ? thr2 : std::min(d * d, thr2);
  }
  return c;
}

cv::Matx33d rotation_of(const cv::Mat& rvec) {
  cv::Mat Rm;
  cv::Rodrigues(rvec, Rm);
  return cv::Matx33d(Rm);
}

cv::Vec3d vec_of(const cv::Mat& tvec) { return {tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2)}; }

// A motion hypothesis from three points with depth: Gauss-Newton on their six reprojection equations,
// from the prediction (frame-to-frame motion is small, so a few steps converge; cheaper than a closed-
// form P3P by an order of magnitude). nullopt when the system is degenerate or does not converge.
std::optional<std::pair<cv::Matx33d, cv::Vec3d>> three_point_motion(const MotionFitPoints& pts,
                                                                    const cv::Matx33d& K,
                                                                    const std::array<int, 3>& idx,
                                                                    const cv::Matx33d& R0,
                                                                    const cv::Vec3d& t0) {
  cv::Matx33d R = R0;
  cv::Vec3d t = t0;
  for (int iter = 0; iter < 4; ++iter) {
    cv::Matx66d H = cv::Matx66d::zeros();
    cv::Vec6d g = cv::Vec6d::all(0.0);
    double err2 = 0.0;
    for (int k : idx) {
      const cv::Point3f& X = pts.cur_3d[static_cast<std::size_t>(k)];
      const cv::Vec3d p = R * cv::Vec3d(X.x, X.y, X.z);
      const cv::Vec3d q = p + t;
      if (q[2] <= 1e-6) return std::nullopt;
      const double iz = 1.0 / q[2];
      const cv::Point2f& o = pts.prev_px[static_cast<std::size_t>(k)];
      const double ru = K(0, 0) * q[0] * iz + K(0, 2) - o.x, rv = K(1, 1) * q[1] * iz + K(1, 2) - o.y;
      err2 += ru * ru + rv * rv;
      // d(u, v)/dq, and dq/d(dw, dt) = [-[p]x | I] for q = exp(dw) p + t + dt.
      const cv::Matx23d Jp(K(0, 0) * iz, 0, -K(0, 0) * q[0] * iz * iz, 0, K(1, 1) * iz,
                           -K(1, 1) * q[1] * iz * iz);
      const cv::Matx33d minus_px(0, p[2], -p[1], -p[2], 0, p[0], p[1], -p[0], 0);
      const cv::Matx23d Jw = Jp * minus_px;
      cv::Matx<double, 2, 6> J;
      for (int r = 0; r < 2; ++r) {
        for (int c = 0; c < 3; ++c) J(r, c) = Jw(r, c), J(r, c + 3) = Jp(r, c);
      }
      H += J.t() * J;
      g += J.t() * cv::Vec2d(ru, rv);
    }
    if (iter > 0 && err2 < 1e-8) break;
    cv::Vec6d d;
    if (!cv::solve(H, -g, d, cv::DECOMP_LU)) return std::nullopt;  // degenerate sample
    cv::Mat dR;
    cv::Rodrigues(cv::Vec3d(d[0], d[1], d[2]), dR);
    R = cv::Matx33d(dR) * R;  // the model the Jacobian is of: q = exp(dw) R X + t + dt
    t += cv::Vec3d(d[3], d[4], d[5]);
  }
  if (!cv::checkRange(cv::Mat(R)) || !cv::checkRange(cv::Mat(t))) return std::nullopt;
  return std::make_pair(R, t);
}

}  // namespace

float epipolar_line_distance(const cv::Matx33d& F, const cv::Point2f& y, const cv::Point2f& x) {
  const cv::Vec3d l = F * cv::Vec3d(y.x, y.y, 1.0);
  const double n = std::hypot(l[0], l[1]);
  return n > 1e-12 ? static_cast<float>(std::abs(l[0] * x.x + l[1] * x.y + l[2]) / n) : -1.f;
}

float homography_transfer_error(const cv::Matx33d& H, const cv::Point2f& y, const cv::Point2f& x) {
  const cv::Vec3d q = H * cv::Vec3d(y.x, y.y, 1.0);
  if (std::abs(q[2]) < 1e-12) return -1.f;
  return static_cast<float>(std::hypot(q[0] / q[2] - x.x, q[1] / q[2] - x.y));
}

std::optional<CameraMotion> fit_camera_motion_msac(const MotionFitPoints& pts, const cv::Matx33d& K,
                                                   const std::optional<CameraMotion>& guess,
                                                   const MsacOptions& opt) {
  const int n = static_cast<int>(pts.cur_3d.size());
  if (n < 4 || pts.prev_px.size() != pts.cur_3d.size() || pts.flat_cur_px.size() != pts.flat_prev_px.size())
    return std::nullopt;
  const double thr2 = opt.threshold_px * opt.threshold_px;
  const cv::Mat Kcv(K);
  const cv::Matx33d Ki = K.inv();
  std::vector<double> r2;
  double best = std::numeric_limits<double>::max();
  std::optional<std::pair<cv::Matx33d, cv::Vec3d>> best_motion;
  const auto consider = [&](const cv::Matx33d& R, const cv::Vec3d& t) {
    squared_residuals(pts, K, R, t, r2);
    double c = truncated_sum(r2, thr2);
    if (c >= best) return;  // the flat points can only add
    c += flat_cost(pts, K, Ki, R, t, opt.flat_threshold_px);
    if (c < best) best = c, best_motion.emplace(R, t);
  };
  const cv::Matx33d R0 = guess ? guess->R : cv::Matx33d::eye();
  const cv::Vec3d t0 = guess ? guess->t : cv::Vec3d(0, 0, 0);
  if (guess) consider(R0, t0);
  cv::RNG rng(0x5eed);
  for (int it = 0; it < opt.iterations; ++it) {
    std::array<int, 3> idx{};
    for (std::size_t k = 0; k < idx.size(); ++k) {
      const auto taken = idx.begin() + static_cast<std::ptrdiff_t>(k);
      do {
        idx[k] = rng.uniform(0, n);
      } while (std::find(idx.begin(), taken, idx[k]) != taken);
    }
    if (const auto h = three_point_motion(pts, K, idx, R0, t0)) consider(h->first, h->second);
  }
  if (!best_motion) return std::nullopt;
  cv::Mat rvec, tvec(best_motion->second, true);
  cv::Rodrigues(cv::Mat(best_motion->first), rvec);
  // Least squares on the best hypothesis' inliers, then again on the refined motion's inliers within
  // max(1 px, half the threshold): with a loose threshold, points just inside it (a slow mover) stop
  // pulling the motion.
  for (const double gate : {opt.threshold_px, std::max(1.0, 0.5 * opt.threshold_px)}) {
    squared_residuals(pts, K, rotation_of(rvec), vec_of(tvec), r2);
    std::vector<cv::Point3f> o;
    std::vector<cv::Point2f> p;
    for (std::size_t i = 0; i < r2.size(); ++i) {
      if (r2[i] <= gate * gate) o.push_back(pts.cur_3d[i]), p.push_back(pts.prev_px[i]);
    }
    if (o.size() < 6) break;
    cv::solvePnPRefineLM(o, p, Kcv, cv::noArray(), rvec, tvec);
  }
  CameraMotion m;
  m.R = rotation_of(rvec);
  m.t = vec_of(tvec);
  squared_residuals(pts, K, m.R, m.t, r2);
  m.inliers = static_cast<int>(std::count_if(r2.begin(), r2.end(), [&](double v) { return v <= thr2; }));
  return m;
}

MsacOptions DynamicFeatureFilter::msac_options() const {
  MsacOptions opt;
  opt.threshold_px =
      cfg_.ego_fit_threshold_px > 0.0 ? cfg_.ego_fit_threshold_px : cfg_.epsilon_reprojection_px;
  opt.flat_threshold_px = cfg_.ego_fit_threshold_px > 0.0
                              ? std::min(cfg_.ego_fit_threshold_px, cfg_.epsilon_epipolar_px)
                              : cfg_.epsilon_epipolar_px;
  opt.iterations = cfg_.ransac_iterations;
  return opt;
}

bool DynamicFeatureFilter::enough_inliers(int inliers, std::size_t points) {
  return static_cast<double>(inliers) >= std::max(6.0, 0.3 * static_cast<double>(points));
}

bool DynamicFeatureFilter::reprojection_residuals(const DynamicInput& in, const std::vector<int>& fit,
                                                  DynamicResult& res, std::vector<float>& eps,
                                                  EgoFit* ego) const {
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
  MotionFitPoints pts;
  std::vector<cv::Point3f>& obj = pts.cur_3d;
  std::vector<cv::Point2f>& img = pts.prev_px;
  for (int i : fit) {
    const auto k = static_cast<std::size_t>(i);
    if (has_z[k]) {
      obj.push_back(X[k]);
      img.push_back(prev[k]);
    } else if (cfg_.ego_fit_flat_points) {  // scored by MSAC only
      pts.flat_cur_px.push_back(cur[k]);
      pts.flat_prev_px.push_back(prev[k]);
    }
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
    int n_inliers = 0;
    if (cfg_.ego_fit == "msac") {
      std::optional<CameraMotion> g;
      if (guess) g = CameraMotion{rotation_of(rvec), vec_of(tvec), 0};
      const std::optional<CameraMotion> m = fit_camera_motion_msac(pts, cv::Matx33d(Kcv), g, msac_options());
      ok = m.has_value();
      if (ok) {
        cv::Rodrigues(cv::Mat(m->R), rvec);
        tvec = cv::Mat(m->t, true);
        n_inliers = m->inliers;
      }
    } else {
      std::vector<int> inliers;
      ok = cv::solvePnPRansac(obj, img, Kcv, cv::noArray(), rvec, tvec, guess, cfg_.ransac_iterations,
                              static_cast<float>(cfg_.epsilon_reprojection_px), cfg_.ransac_confidence,
                              inliers, cv::SOLVEPNP_ITERATIVE);
      n_inliers = static_cast<int>(inliers.size());
    }
    ok = ok && enough_inliers(n_inliers, obj.size());
    res.ego_inliers = ok ? n_inliers : 0;
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
  const cv::Matx33d Kx(Kcv);
  const DepthlessResidual depthless(Kx, Kx.inv(), R, t);  // points without usable depth
  for (std::size_t i = 0; i < n; ++i) {
    if (has_z[i]) {
      const cv::Vec3d q = R * cv::Vec3d(X[i].x, X[i].y, X[i].z) + t;
      if (q[2] <= 1e-6) continue;
      const double u = fx * q[0] / q[2] + cx, v = fy * q[1] / q[2] + cy;
      res.flow_residual[i] = static_cast<float>(std::hypot(u - prev[i].x, v - prev[i].y));
      eps[i] = static_cast<float>(cfg_.epsilon_reprojection_px);
    } else {
      res.flow_residual[i] = depthless(cur[i], prev[i]);
      eps[i] = static_cast<float>(cfg_.epsilon_epipolar_px);
    }
  }
  if (cfg_.depthless_homography) depthless_homography_residuals(fit, has_z, res);
  res.residual_used = "reprojection";
  if (ego != nullptr) *ego = EgoFit{CameraMotion{R, t, res.ego_inliers}, std::move(X), std::move(has_z)};
  return true;
}

bool DynamicFeatureFilter::explained_by_camera(const Eigen::Matrix3d& Ke, const CameraMotion& motion,
                                               const EgoFit& ego, const std::vector<cv::Point2f>& prev_px,
                                               const std::vector<std::size_t>& background,
                                               const std::vector<std::size_t>& object) const {
  MotionFitPoints pts;
  std::vector<int> group;  // 0 background, 1 object
  for (const auto& [idx, g] : {std::pair{&background, 0}, std::pair{&object, 1}}) {
    for (std::size_t i : *idx) {
      if (!ego.has_z[i]) continue;
      pts.cur_3d.push_back(ego.X[i]);
      pts.prev_px.push_back(prev_px[i]);
      group.push_back(g);
    }
  }
  if (pts.cur_3d.size() < 8) return false;  // as the first fit needs
  cv::Matx33d K;
  cv::eigen2cv(Ke, K);
  cv::Mat rvec, tvec = cv::Mat(motion.t, true);
  cv::Rodrigues(cv::Mat(motion.R), rvec);
  const auto R = [&] {
    cv::Mat Rm;
    cv::Rodrigues(rvec, Rm);
    return cv::Matx33d(Rm);
  };
  const auto t = [&] { return cv::Vec3d(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2)); };
  const double eps2 = cfg_.epsilon_reprojection_px * cfg_.epsilon_reprojection_px;
  std::vector<double> r2(pts.cur_3d.size(), 0.0);
  // Least squares from the first fit, then again without the points it leaves beyond the threshold
  // (an arm that moves must not drag the joint motion).
  for (int round = 0; round < 2; ++round) {
    if (round == 1) squared_residuals(pts, K, R(), t(), r2);
    std::vector<cv::Point3f> o;
    std::vector<cv::Point2f> p;
    for (std::size_t i = 0; i < r2.size(); ++i) {
      if (r2[i] > eps2) continue;
      o.push_back(pts.cur_3d[i]);
      p.push_back(pts.prev_px[i]);
    }
    if (o.size() < 6) return false;
    cv::solvePnP(o, p, K, cv::noArray(), rvec, tvec, true, cv::SOLVEPNP_ITERATIVE);
  }
  // Only a small correction of the first fit counts: two depth layers are explained exactly by some
  // rotation and translation together, a person walking in front of a wall included.
  const cv::Matx33d dR = R() * motion.R.t();
  const double dang = std::acos(std::clamp((cv::trace(dR) - 1.0) / 2.0, -1.0, 1.0)) * 180.0 / M_PI;
  if (cv::norm(t() - motion.t) > cfg_.joint_fit_max_change_m || dang > cfg_.joint_fit_max_change_deg)
    return false;
  squared_residuals(pts, K, R(), t(), r2);
  std::array<int, 2> total{0, 0}, moving{0, 0};
  for (std::size_t i = 0; i < r2.size(); ++i) {
    ++total[static_cast<std::size_t>(group[i])];
    moving[static_cast<std::size_t>(group[i])] += r2[i] > eps2 ? 1 : 0;
  }
  for (std::size_t g = 0; g < 2; ++g) {
    if (total[g] == 0 || static_cast<double>(moving[g]) >= cfg_.moving_ratio_threshold * total[g])
      return false;
  }
  return true;
}

std::optional<bool> DynamicFeatureFilter::moved_over_baseline(const DynamicInput& in,
                                                              const DynamicResult& res, const EgoFit& ego,
                                                              const std::vector<std::size_t>& background,
                                                              const std::vector<std::size_t>& object) const {
  // The stored frames end at this one and are consecutive; the span is as long as they reach.
  if (stored_.size() < 3 || stored_.back().frame_index != in.frame_index) return std::nullopt;
  std::vector<std::size_t> idx;  // background first, then the object
  for (const auto* group : {&background, &object}) {
    for (std::size_t i : *group) {
      if (ego.has_z[i]) idx.push_back(i);
    }
  }
  // Follow the points back from the previous frame (their flow is known) to the oldest stored one,
  // one frame step at a time: a small motion per step keeps LK in its basin.
  std::vector<cv::Point2f> pos;
  for (std::size_t i : idx) pos.push_back(res.flow_prev[i]);
  std::vector<bool> alive(idx.size(), true);
  const cv::Size win(cfg_.lk_window, cfg_.lk_window);
  const cv::TermCriteria term(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 20, 0.03);
  std::vector<cv::Point2f> next;
  std::vector<uchar> st;
  std::vector<float> err;
  const cv::Size image = stored_.back().pyramid.front().size();
  const cv::Rect2f bounds(0.f, 0.f, static_cast<float>(image.width), static_cast<float>(image.height));
  // x_oldest = R x_cur + t, chained from the per-frame camera fits (the guess of the span's fit).
  std::optional<CameraMotion> chained = stored_.back().motion;
  for (std::size_t s = stored_.size() - 1; s-- > 1;) {
    const StoredFrame& from = stored_[s];
    const StoredFrame& to = stored_[s - 1];
    next = pos;
    cv::calcOpticalFlowPyrLK(from.pyramid, to.pyramid, pos, next, st, err, win, cfg_.lk_levels, term,
                             cv::OPTFLOW_USE_INITIAL_FLOW);
    for (std::size_t k = 0; k < idx.size(); ++k) alive[k] = alive[k] && st[k] && bounds.contains(next[k]);
    pos.swap(next);
    if (chained && from.motion) {
      chained->t = from.motion->R * chained->t + from.motion->t;
      chained->R = from.motion->R * chained->R;
    } else {
      chained.reset();
    }
  }
  // The span's camera motion, fitted on the background as the one-step fit is.
  std::vector<cv::Point2f> oldest_px(res.flow_prev.size());
  MotionFitPoints pts;
  std::vector<std::size_t> bg_alive, obj_alive;
  std::size_t n_bg = 0;  // idx holds the background's points first
  for (std::size_t i : background) n_bg += ego.has_z[i] ? 1 : 0;
  for (std::size_t k = 0; k < idx.size(); ++k) {
    if (!alive[k]) continue;
    oldest_px[idx[k]] = pos[k];
    if (k < n_bg) {
      bg_alive.push_back(idx[k]);
      pts.cur_3d.push_back(ego.X[idx[k]]);
      pts.prev_px.push_back(pos[k]);
    } else {
      obj_alive.push_back(idx[k]);
    }
  }
  if (pts.cur_3d.size() < 8 || static_cast<int>(obj_alive.size()) < cfg_.min_points_to_decide)
    return std::nullopt;
  cv::Matx33d K;
  cv::eigen2cv(*in.K, K);
  const std::optional<CameraMotion> m = fit_camera_motion_msac(pts, K, chained, msac_options());
  if (!m || !enough_inliers(m->inliers, pts.cur_3d.size())) return std::nullopt;
  // Under the background's motion: the object's moving share, then the joint refit, as for one step.
  const double eps2 = cfg_.epsilon_reprojection_px * cfg_.epsilon_reprojection_px;
  MotionFitPoints obj;
  for (std::size_t i : obj_alive) {
    obj.cur_3d.push_back(ego.X[i]);
    obj.prev_px.push_back(oldest_px[i]);
  }
  std::vector<double> r2;
  squared_residuals(obj, K, m->R, m->t, r2);
  const auto obj_moving = std::count_if(r2.begin(), r2.end(), [&](double v) { return v > eps2; });
  if (static_cast<double>(obj_moving) < cfg_.moving_ratio_threshold * static_cast<double>(r2.size()))
    return false;
  squared_residuals(pts, K, m->R, m->t, r2);
  std::vector<std::size_t> bg_inliers;
  for (std::size_t k = 0; k < bg_alive.size(); ++k) {
    if (r2[k] <= eps2) bg_inliers.push_back(bg_alive[k]);
  }
  return !explained_by_camera(*in.K, *m, ego, oldest_px, bg_inliers, obj_alive);
}

void DynamicFeatureFilter::depthless_homography_residuals(const std::vector<int>& fit,
                                                          const std::vector<bool>& has_z,
                                                          DynamicResult& res) const {
  const auto& cur = res.flow_points;
  const auto& prev = res.flow_prev;
  std::vector<cv::Point2f> p, c;
  for (int i : fit) {
    const auto k = static_cast<std::size_t>(i);
    if (has_z[k]) continue;
    p.push_back(prev[k]);
    c.push_back(cur[k]);
  }
  if (static_cast<int>(p.size()) < cfg_.min_static_points) return;  // validated >= 8
  cv::Mat mask;
  const cv::Mat H = cv::findHomography(p, c, cv::RANSAC, cfg_.epsilon_epipolar_px, mask,
                                       cfg_.ransac_iterations * 10, cfg_.ransac_confidence);
  // Only a homography most of them follow describes the far scene; else a person or mixed depths.
  if (H.empty() || 2 * cv::countNonZero(mask) < static_cast<int>(p.size())) return;
  const cv::Matx33d M(H);
  for (std::size_t i = 0; i < cur.size(); ++i) {
    if (has_z[i] || res.flow_residual[i] < 0.f) continue;
    const float r = homography_transfer_error(M, prev[i], cur[i]);
    if (r >= 0.f) res.flow_residual[i] = std::min(res.flow_residual[i], r);
  }
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
    res.flow_residual[i] =
        use_h ? homography_transfer_error(M, prev[i], cur[i]) : epipolar_line_distance(M, prev[i], cur[i]);
    eps[i] = static_cast<float>(cfg_.epsilon_epipolar_px);
  }
  res.residual_used = use_h ? "homography" : "epipolar";
  res.ego_inliers = use_h ? h_in : f_in;
}

}  // namespace sp::dyn
