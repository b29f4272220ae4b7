#include "stillpoint/tracking/anchor_refiner.hpp"

#include <algorithm>
#include <cmath>
#include <opencv2/video/tracking.hpp>

#include "stillpoint/tracking/pose_guard.hpp"

namespace sp::track {

AnchorRefinerConfig AnchorRefinerConfig::from_yaml(const ConfigReader& r) {
  AnchorRefinerConfig c;
  r.read("enabled", c.enabled);
  r.read("anchors", c.anchors, 1, 20);
  r.read("window", c.window, 5, 51);
  r.read("pyramid_levels", c.pyramid_levels, 0, 5);
  r.read("max_shift", c.max_shift, 0.1, 10.0);
  r.read("max_roll_deg", c.max_roll_deg, 0.0, 45.0);
  r.read("max_scale_change", c.max_scale_change, 0.0, 1.0);
  r.read("max_view_change_deg", c.max_view_change_deg, 0.0, 90.0);
  r.read("max_error", c.max_error, 0.1, 255.0);
  r.read("level0_weight", c.level0_weight);
  r.read("refined_weight", c.refined_weight, 0.1, 100.0);
  r.read("max_round_trip", c.max_round_trip, 0.0, 10.0);
  r.read("skip_suspect", c.skip_suspect);
  r.read("aligned_only_min", c.aligned_only_min, 0, 100000);
  r.read("aligned_only_max_translation_m", c.aligned_only_max_translation_m, 0.0, 1.0);
  r.read("aligned_only_max_rotation_deg", c.aligned_only_max_rotation_deg, 0.0, 45.0);
  r.read_choice("aligned_only_unaligned", c.aligned_only_unaligned, {"kept", "tracked"});
  return c;
}

AnchorRefiner::AnchorRefiner(AnchorRefinerConfig config, geo::CameraIntrinsics camera,
                             map::ScalePyramid pyramid)
    : config_(config), camera_(camera), pyramid_(std::move(pyramid)) {}

cv::Point2f AnchorRefiner::raw(const cv::Point2f& undistorted) const {
  if (!camera_.has_distortion()) return undistorted;
  const Eigen::Vector2d d = camera_.distort({undistorted.x, undistorted.y});
  return {static_cast<float>(d.x()), static_cast<float>(d.y())};
}

void AnchorRefiner::set_anchor(map::KeyframeId id, const Frame& frame) {
  if (!config_.enabled || frame.gray.empty() || frame.gray.type() != CV_8UC1) return;
  if (anchors_.size() >= static_cast<std::size_t>(config_.anchors)) anchors_.erase(anchors_.begin());
  Anchor& a = anchors_.emplace_back();
  a.id = id;
  a.T_cw = frame.T_cw;
  // The anchor's pyramid is built once; every later frame aligns against it.
  cv::buildOpticalFlowPyramid(frame.gray, a.pyramid, cv::Size(config_.window, config_.window),
                              config_.pyramid_levels);
  a.raw.resize(frame.features.size());
  for (std::size_t i = 0; i < frame.features.size(); ++i) a.raw[i] = raw(frame.features.keypoints[i].pt);
}

bool AnchorRefiner::aligned_only(const LocalMapSnapshot& map, const geo::SE3& T_cw, int aligned) const {
  if (config_.aligned_only_min <= 0 || aligned < config_.aligned_only_min) return false;
  for (const Anchor& a : anchors_) {
    const LocalMapSnapshot::Pose* kf = map.pose(a.id);
    if (kf == nullptr || kf->bad) continue;
    if (pose_deviation(T_cw, kf->T_cw)
            .within(config_.aligned_only_max_translation_m, config_.aligned_only_max_rotation_deg))
      return true;
  }
  return false;
}

std::vector<map::KeyframeId> AnchorRefiner::anchor_ids() const {
  std::vector<map::KeyframeId> ids;
  for (const Anchor& a : anchors_) ids.push_back(a.id);
  return ids;
}

int AnchorRefiner::refine(const LocalMapSnapshot& map, Frame& frame, std::vector<bool>& refined) {
  refined.assign(frame.features.size(), false);
  if (anchors_.empty() || frame.gray.empty() || !frame.has_pose) return 0;
  ++stats_.frames;

  // Which anchors a translation-only patch alignment can use: it fails under in-plane rotation.
  const double max_view_cos = std::cos(config_.max_view_change_deg * M_PI / 180.0);
  const Eigen::Vector3d c_now = frame.camera_center();
  std::vector<bool> usable(anchors_.size(), false);
  std::vector<Eigen::Vector3d> centers(anchors_.size());
  for (std::size_t a = 0; a < anchors_.size(); ++a) {
    const LocalMapSnapshot::Pose* kf = map.pose(anchors_[a].id);
    if (kf == nullptr || kf->bad) continue;
    anchors_[a].T_cw = kf->T_cw;  // bundle adjustment may have moved it
    const Eigen::Matrix3d R_rel = frame.T_cw.rotation() * kf->T_cw.rotation().transpose();
    usable[a] = std::abs(geo::so3_log(R_rel).z()) * 180.0 / M_PI <= config_.max_roll_deg;
    centers[a] = kf->T_cw.inverse().translation();
  }

  // Per anchor (newest first wins): the features to align and their anchor positions.
  struct Job {
    std::vector<cv::Point2f> from, to;
    std::vector<std::size_t> feature_of;
  };
  std::vector<Job> jobs(anchors_.size());
  for (std::size_t i = 0; i < frame.points.size(); ++i) {
    if (frame.points[i] == map::kNoPoint || frame.outlier[i]) continue;
    if (config_.skip_suspect && i < frame.suspect.size() && frame.suspect[i]) continue;
    const LocalMapSnapshot::Point* p = map.live_point(frame.points[i]);
    if (p == nullptr) continue;
    const double z_now = (frame.T_cw * p->position).z();
    if (z_now <= 0) continue;
    const Eigen::Vector3d ray_now = (c_now - p->position).normalized();
    for (std::size_t a = anchors_.size(); a-- > 0;) {
      if (!usable[a]) continue;
      const Anchor& anchor = anchors_[a];
      const int feature = map.anchor_feature(*p, anchor.id);
      if (feature < 0 || static_cast<std::size_t>(feature) >= anchor.raw.size()) continue;
      const double z_anchor = (anchor.T_cw * p->position).z();
      if (z_anchor <= 0 || std::abs(z_anchor / z_now - 1.0) > config_.max_scale_change) continue;
      if ((centers[a] - p->position).normalized().dot(ray_now) < max_view_cos) continue;
      jobs[a].from.push_back(anchor.raw[static_cast<std::size_t>(feature)]);
      jobs[a].to.push_back(raw(frame.features.keypoints[i].pt));
      jobs[a].feature_of.push_back(i);
      break;
    }
  }

  int moved = 0;
  const cv::Size window(config_.window, config_.window);
  const cv::TermCriteria stop(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 20, 0.01);
  for (std::size_t a = 0; a < anchors_.size(); ++a) {
    Job& job = jobs[a];
    if (job.from.empty()) continue;
    stats_.candidates += job.from.size();
    const std::vector<cv::Point2f> detected = job.to;
    std::vector<unsigned char> status;
    std::vector<float> error;
    cv::calcOpticalFlowPyrLK(anchors_[a].pyramid, frame.gray, job.from, job.to, status, error, window,
                             config_.pyramid_levels, stop, cv::OPTFLOW_USE_INITIAL_FLOW);
    std::vector<unsigned char> back_status;
    std::vector<cv::Point2f> back;
    if (config_.max_round_trip > 0) {
      // Occlusion check: the aligned patch tracked back must land on the anchor's feature.
      back = job.from;
      std::vector<float> back_error;
      cv::calcOpticalFlowPyrLK(frame.gray, anchors_[a].pyramid[0], job.to, back, back_status, back_error,
                               window, 0, stop, cv::OPTFLOW_USE_INITIAL_FLOW);
    }
    for (std::size_t k = 0; k < job.from.size(); ++k) {
      if (!status[k] || error[k] > config_.max_error) continue;
      if (config_.max_round_trip > 0 &&
          (!back_status[k] ||
           std::hypot(back[k].x - job.from[k].x, back[k].y - job.from[k].y) > config_.max_round_trip))
        continue;
      const std::size_t i = job.feature_of[k];
      cv::KeyPoint& kp = frame.features.keypoints[i];
      const auto level = static_cast<std::size_t>(std::clamp(kp.octave, 0, pyramid_.levels - 1));
      const double level_px = level < pyramid_.scale.size() ? pyramid_.scale[level] : 1.0;
      const cv::Point2f shift = job.to[k] - detected[k];
      if (std::hypot(shift.x, shift.y) > config_.max_shift * level_px) continue;
      // The shift measured on the raw image is applied to the undistorted position (the distortion is
      // locally a near-identity over a pixel).
      kp.pt += shift;
      if (frame.features.u_right[i] >= 0) frame.features.u_right[i] += shift.x;
      refined[i] = true;
      ++moved;
    }
  }
  stats_.refined += static_cast<std::size_t>(moved);
  return moved;
}

}  // namespace sp::track
