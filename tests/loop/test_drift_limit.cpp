// The loop drift limit alone: path and correction measured on known transforms, and the rule that a
// correction beyond base + ratio x travelled is refused (a look-alike place), one within it accepted.
#include <gtest/gtest.h>

#include <cmath>

#include "stillpoint/loop/drift_limit.hpp"

namespace sp::loop {
namespace {

// T_cw of a camera at centre c, turned by yaw_deg about the world z axis.
geo::SE3 camera(const Eigen::Vector3d& c, double yaw_deg) {
  const Eigen::Quaterniond q_wc(Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitZ()));
  return geo::SE3(q_wc, c).inverse();
}

TEST(DriftLimit, PathAndCorrectionOfKnownTransforms) {
  // A 3-4-5 walk: 3 m along x, then 4 m along y, turning 90 deg at the corner.
  const std::vector<geo::SE3> poses{camera({0, 0, 0}, 0), camera({3, 0, 0}, 0), camera({3, 4, 0}, 90)};
  const Motion path = travelled(poses);
  EXPECT_NEAR(path.metres, 7.0, 1e-9);
  EXPECT_NEAR(path.degrees, 90.0, 1e-9);
  const Motion c = correction(camera({1, 2, 0}, 10), camera({4, 6, 0}, -20));
  EXPECT_NEAR(c.metres, 5.0, 1e-9);
  EXPECT_NEAR(c.degrees, 30.0, 1e-9);
  EXPECT_NEAR(travelled({}).metres, 0.0, 0.0);
}

TEST(DriftLimit, AllowanceGrowsWithThePathTravelled) {
  DriftLimitConfig cfg;  // 0.3 m + 10 %, 10 deg + 10 %
  const Motion a = allowance({5.0, 200.0}, cfg);
  EXPECT_NEAR(a.metres, 0.8, 1e-12);
  EXPECT_NEAR(a.degrees, 30.0, 1e-12);
  // A true loop after a 13.5 m walk that drifted 0.2 m / 3 deg: accepted.
  EXPECT_TRUE(plausible({0.2, 3.0}, {13.5, 360.0}, cfg));
  // The half-turn look-alike of office_a: 3.1 m / 180 deg after 5.6 m / 234 deg: refused.
  EXPECT_FALSE(plausible({3.1, 180.0}, {5.6, 234.0}, cfg));
  // Each bound alone refuses.
  EXPECT_FALSE(plausible({0.81, 1.0}, {5.0, 200.0}, cfg));
  EXPECT_FALSE(plausible({0.1, 30.5}, {5.0, 200.0}, cfg));
  cfg.enabled = false;
  EXPECT_TRUE(plausible({3.1, 180.0}, {5.6, 234.0}, cfg));
}

}  // namespace
}  // namespace sp::loop
