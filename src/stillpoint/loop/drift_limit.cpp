#include "stillpoint/loop/drift_limit.hpp"

#include "stillpoint/tracking/pose_guard.hpp"

namespace sp::loop {

Motion travelled(const std::vector<geo::SE3>& poses_cw) {
  Motion m;
  for (std::size_t i = 1; i < poses_cw.size(); ++i) {
    const Motion step = correction(poses_cw[i - 1], poses_cw[i]);
    m.metres += step.metres;
    m.degrees += step.degrees;
  }
  return m;
}

Motion correction(const geo::SE3& before_cw, const geo::SE3& after_cw) {
  const track::PoseDeviation d = track::pose_deviation(after_cw, before_cw);
  return {d.translation_m, d.rotation_deg};
}

Motion allowance(const Motion& path, const DriftLimitConfig& config) {
  return {config.base_m + config.ratio * path.metres, config.base_deg + config.ratio * path.degrees};
}

bool plausible(const Motion& c, const Motion& path, const DriftLimitConfig& config) {
  if (!config.enabled) return true;
  const Motion a = allowance(path, config);
  return c.metres <= a.metres && c.degrees <= a.degrees;
}

}  // namespace sp::loop
