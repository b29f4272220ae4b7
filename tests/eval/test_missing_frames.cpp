#include <gtest/gtest.h>

#include "stillpoint/common/error.hpp"
#include "stillpoint/eval/missing_frames.hpp"

namespace sp::eval {
namespace {

// A camera moving 1 cm per frame along x while turning 1 degree per frame about y, at 30 Hz.
io::StampedPose truth(int frame) {
  const double yaw = frame * M_PI / 180.0;
  return {frame / 30.0, Eigen::Vector3d(0.01 * frame, 0.0, 0.0),
          Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY()))};
}

std::vector<double> frame_stamps(int n) {
  std::vector<double> s;
  for (int i = 0; i < n; ++i) s.push_back(truth(i).stamp);
  return s;
}

// Frames 0-2 and 7-9 estimated (exactly), 3-6 lost.
std::vector<io::StampedPose> with_gap() {
  std::vector<io::StampedPose> est;
  for (int i : {0, 1, 2, 7, 8, 9}) est.push_back(truth(i));
  return est;
}

double angle_deg(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) {
  return a.angularDistance(b) * 180.0 / M_PI;
}

TEST(MissingFrames, SkipLeavesTheEstimateAsWritten) {
  const auto f = fill_missing_frames(frame_stamps(10), with_gap(), MissingFrames::Skip);
  ASSERT_EQ(f.poses.size(), 6u);
  EXPECT_EQ(f.held + f.interpolated + f.before_first, 0u);
}

TEST(MissingFrames, HoldRepeatsTheLastPoseBeforeTheGap) {
  const auto f = fill_missing_frames(frame_stamps(10), with_gap(), MissingFrames::Hold);
  ASSERT_EQ(f.poses.size(), 10u);
  EXPECT_EQ(f.held, 4u);
  for (int i = 3; i <= 6; ++i) {
    EXPECT_NEAR(f.poses[i].stamp, truth(i).stamp, 1e-12);
    EXPECT_NEAR((f.poses[i].t - truth(2).t).norm(), 0.0, 1e-12);
    EXPECT_NEAR(angle_deg(f.poses[i].q, truth(2).q), 0.0, 1e-9);
  }
}

TEST(MissingFrames, InterpolateRecoversAConstantMotionAcrossTheGap) {
  const auto f = fill_missing_frames(frame_stamps(10), with_gap(), MissingFrames::Interpolate);
  ASSERT_EQ(f.poses.size(), 10u);
  EXPECT_EQ(f.interpolated, 4u);
  EXPECT_EQ(f.held, 0u);
  // Constant velocity in translation and about one axis: the geodesic between frames 2 and 7 is it.
  for (int i = 0; i < 10; ++i) {
    EXPECT_NEAR(f.poses[i].stamp, truth(i).stamp, 1e-12) << i;
    EXPECT_NEAR((f.poses[i].t - truth(i).t).norm(), 0.0, 1e-9) << i;
    EXPECT_NEAR(angle_deg(f.poses[i].q, truth(i).q), 0.0, 1e-6) << i;
  }
}

TEST(MissingFrames, AGapAtTheEndOrBetweenMapsIsHeldAndNothingPrecedesTheFirstPose) {
  std::vector<io::StampedPose> est;
  for (int i : {2, 3, 4, 7, 8}) est.push_back(truth(i));
  // Frames 2-4 in map 0, 7-8 in map 1 (its own frame): frames 5-6 must not blend the two.
  const auto f = fill_missing_frames(frame_stamps(10), est, MissingFrames::Interpolate, {0, 0, 0, 1, 1});
  EXPECT_EQ(f.before_first, 2u);  // frames 0 and 1
  EXPECT_EQ(f.interpolated, 0u);
  EXPECT_EQ(f.held, 3u);  // 5 and 6 hold frame 4, 9 holds frame 8
  ASSERT_EQ(f.poses.size(), 8u);
  EXPECT_NEAR((f.poses[3].t - truth(4).t).norm(), 0.0, 1e-12);  // frame 5
  EXPECT_NEAR((f.poses[7].t - truth(8).t).norm(), 0.0, 1e-12);  // frame 9
  EXPECT_NEAR(f.poses[7].stamp, truth(9).stamp, 1e-12);
  // The same maps for both sides interpolate.
  const auto g = fill_missing_frames(frame_stamps(10), est, MissingFrames::Interpolate, {0, 0, 0, 0, 0});
  EXPECT_EQ(g.interpolated, 2u);
  EXPECT_THROW((void)fill_missing_frames(frame_stamps(10), est, MissingFrames::Hold, {0, 0}), Error);
}

TEST(MissingFrames, StampsWithinTheToleranceCountAsTheFrame) {
  // A peer that prints stamps with fewer digits: 0.4 ms off each frame is still that frame.
  std::vector<io::StampedPose> est;
  for (int i : {0, 1, 2, 3}) {
    est.push_back(truth(i));
    est.back().stamp += 0.0004;
  }
  const auto f = fill_missing_frames(frame_stamps(4), est, MissingFrames::Hold);
  EXPECT_EQ(f.held, 0u);
  EXPECT_EQ(f.poses.size(), 4u);
}

}  // namespace
}  // namespace sp::eval
