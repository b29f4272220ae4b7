#include "stillpoint/tracking/pose_guard.hpp"

#include <cmath>

namespace sp::track {

PoseGuardConfig PoseGuardConfig::from_yaml(const ConfigReader& r) {
  PoseGuardConfig c;
  r.read("enabled", c.enabled);
  r.read("max_translation_m", c.max_translation_m, 0.001, 1.0);
  r.read("max_rotation_deg", c.max_rotation_deg, 0.05, 45.0);
  r.read("min_suspect_share", c.min_suspect_share, 0.0, 1.0);
  r.read("keyframe_below_reference_share", c.keyframe_below_reference_share, 0.0, 1.0);
  return c;
}

PoseDeviation pose_deviation(const geo::SE3& a_cw, const geo::SE3& b_cw) {
  PoseDeviation d;
  d.translation_m = (a_cw.inverse().translation() - b_cw.inverse().translation()).norm();
  d.rotation_deg = Eigen::AngleAxisd((a_cw * b_cw.inverse()).rotation()).angle() * 180.0 / M_PI;
  return d;
}

bool PoseGuardRules::is_jump(const PoseDeviation& d) const {
  return config_.enabled && !d.within(config_.max_translation_m, config_.max_rotation_deg);
}

bool PoseGuardRules::blames_suspects(int inliers, int suspect_inliers) const {
  return suspect_inliers > 0 &&
         static_cast<double>(suspect_inliers) >= config_.min_suspect_share * static_cast<double>(inliers);
}

bool PoseGuardRules::accepts_resolve(const PoseDeviation& before, const PoseDeviation& after,
                                     int inliers_after, int min_inliers) const {
  return inliers_after >= min_inliers && normalized(after) < normalized(before);
}

bool PoseGuardRules::keyframe_despite_jump(int inliers, int reference_tracked) const {
  return static_cast<double>(inliers) <
         config_.keyframe_below_reference_share * static_cast<double>(reference_tracked);
}

double PoseGuardRules::normalized(const PoseDeviation& d) const {
  return d.translation_m / config_.max_translation_m + d.rotation_deg / config_.max_rotation_deg;
}

}  // namespace sp::track
