#include "stillpoint/loop/drift_limit.hpp"

#include <cmath>

namespace sp::loop {
namespace {
double angle_deg(const Eigen::Matrix3d& R) { return geo::so3_log(R).norm() * 180.0 / M_PI; }
}  // namespace

Motion travelled(const std::vector<geo::SE3>& poses_cw) {
  Motion m;
  for (std::size_t i = 1; i < poses_cw.size(); ++i) {
    m.metres += (poses_cw[i].inverse().translation() - poses_cw[i - 1].inverse().translation()).norm();
    m.degrees += angle_deg(poses_cw[i].rotation() * poses_cw[i - 1].rotation().transpose());
  }
  return m;
}

Motion correction(const geo::SE3& before_cw, const geo::SE3& after_cw) {
  return {(after_cw.inverse().translation() - before_cw.inverse().translation()).norm(),
          angle_deg(after_cw.rotation() * before_cw.rotation().transpose())};
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
