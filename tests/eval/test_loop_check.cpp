#include <gtest/gtest.h>

#include "stillpoint/eval/loop_check.hpp"

namespace sp::eval {
namespace {

io::StampedPose at(double stamp, const geo::SE3& T_wc) {
  return {stamp, T_wc.translation(), T_wc.quaternion()};
}

geo::SE3 pose(double yaw, double x, double y, double z) {
  return geo::SE3(Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY())),
                  Eigen::Vector3d(x, y, z));
}

TEST(LoopCheck, ExactRelativePoseIsTrueAndAWrongPlaceIsFalse) {
  const geo::SE3 T_wm = pose(0.3, 1.0, 0.0, 2.0);
  const geo::SE3 T_wq = pose(0.5, 1.4, 0.1, 1.7);
  const std::vector<io::StampedPose> gt{at(1.0, T_wm), at(2.0, pose(0, 5, 5, 5)), at(3.0, T_wq)};
  const geo::SE3 truth = T_wq.inverse() * T_wm;
  const auto ok = check_loop(gt, 3.0, 1.0, truth);
  ASSERT_TRUE(ok.has_value());
  EXPECT_TRUE(ok->is_true);
  EXPECT_NEAR(ok->translation_error_m, 0.0, 1e-9);
  EXPECT_NEAR(ok->rotation_error_deg, 0.0, 1e-6);
  EXPECT_NEAR(ok->gt_distance_m, truth.translation().norm(), 1e-12);
  // 5 cm and 2 degrees off: still the same place.
  const auto near = check_loop(gt, 3.0, 1.0, pose(2.0 * M_PI / 180.0, 0.05, 0, 0) * truth);
  ASSERT_TRUE(near.has_value());
  EXPECT_TRUE(near->is_true);
  EXPECT_NEAR(near->rotation_error_deg, 2.0, 1e-6);
  // The loop believed the match was somewhere else: 1 m off.
  const auto wrong = check_loop(gt, 3.0, 1.0, pose(0, 1.0, 0, 0) * truth);
  ASSERT_TRUE(wrong.has_value());
  EXPECT_FALSE(wrong->is_true);
  EXPECT_NEAR(wrong->translation_error_m, 1.0, 1e-9);
  // Right place, wrong orientation by 20 degrees.
  EXPECT_FALSE(check_loop(gt, 3.0, 1.0, pose(20.0 * M_PI / 180.0, 0, 0, 0) * truth)->is_true);
}

TEST(LoopCheck, NoGroundTruthNearAStampGivesNothing) {
  const std::vector<io::StampedPose> gt{at(1.0, pose(0, 0, 0, 0)), at(3.0, pose(0, 1, 0, 0))};
  EXPECT_FALSE(check_loop(gt, 3.0, 2.0, geo::SE3()).has_value());
  EXPECT_TRUE(check_loop(gt, 3.01, 0.99, geo::SE3()).has_value());  // within 20 ms
}

}  // namespace
}  // namespace sp::eval
