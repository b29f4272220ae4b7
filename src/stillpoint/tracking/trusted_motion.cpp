#include "stillpoint/tracking/trusted_motion.hpp"

#include <algorithm>

namespace sp::track {

void TrustedMotion::add(std::size_t frame_index, const geo::SE3& T_cw) {
  if (!poses_.empty() && poses_.back().index + 1 != frame_index) poses_.clear();
  poses_.push_back({frame_index, T_cw});
  while (poses_.size() > static_cast<std::size_t>(std::max(window_, 1))) poses_.pop_front();
}

void TrustedMotion::move_frame(const geo::SE3& S_new_old) {
  // T_cw maps world to camera: in the new world frame T_cw' = T_cw * S^-1.
  const geo::SE3 S_old_new = S_new_old.inverse();
  for (Stamped& p : poses_) p.T_cw = p.T_cw * S_old_new;
}

std::optional<geo::SE3> TrustedMotion::extrapolate(std::size_t frame_index) const {
  if (poses_.empty()) return std::nullopt;
  const Stamped& last = poses_.back();
  if (poses_.size() < 2 || window_ < 2 || max_frames_ <= 0 || frame_index <= last.index) return last.T_cw;
  const Stamped& first = poses_.front();
  // The mean per-frame step in the camera frame (T_cur_prev), as the constant-velocity model's.
  const geo::Vec6 step =
      (last.T_cw * first.T_cw.inverse()).log() / static_cast<double>(last.index - first.index);
  const double frames = static_cast<double>(
      std::min<std::size_t>(frame_index - last.index, static_cast<std::size_t>(max_frames_)));
  return geo::SE3::exp(step * frames) * last.T_cw;
}

}  // namespace sp::track
