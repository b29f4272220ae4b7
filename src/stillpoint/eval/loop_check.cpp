#include "stillpoint/eval/loop_check.hpp"

#include <algorithm>
#include <cmath>

namespace sp::eval {

namespace {
std::optional<geo::SE3> pose_at(const std::vector<io::StampedPose>& gt, double stamp, double max_dt) {
  const auto it = std::lower_bound(gt.begin(), gt.end(), stamp,
                                   [](const io::StampedPose& p, double s) { return p.stamp < s; });
  const io::StampedPose* best = nullptr;
  if (it != gt.end()) best = &*it;
  if (it != gt.begin() && (best == nullptr || stamp - std::prev(it)->stamp < best->stamp - stamp))
    best = &*std::prev(it);
  if (best == nullptr || std::abs(best->stamp - stamp) > max_dt) return std::nullopt;
  return geo::SE3(best->q, best->t);  // T_world_camera
}
}  // namespace

std::optional<LoopCheck> check_loop(const std::vector<io::StampedPose>& gt, double query_stamp,
                                    double match_stamp, const geo::SE3& T_query_match,
                                    const LoopCheckThresholds& thresholds) {
  const auto T_wq = pose_at(gt, query_stamp, thresholds.max_time_difference_s);
  const auto T_wm = pose_at(gt, match_stamp, thresholds.max_time_difference_s);
  if (!T_wq || !T_wm) return std::nullopt;
  const geo::SE3 gt_qm = T_wq->inverse() * *T_wm;
  const geo::SE3 error = gt_qm.inverse() * T_query_match;
  LoopCheck c;
  c.translation_error_m = error.translation().norm();
  c.rotation_error_deg = Eigen::AngleAxisd(error.quaternion().normalized()).angle() * 180.0 / M_PI;
  c.gt_distance_m = gt_qm.translation().norm();
  c.is_true = c.translation_error_m <= thresholds.max_translation_m &&
              c.rotation_error_deg <= thresholds.max_rotation_deg;
  return c;
}

}  // namespace sp::eval
