// Relocalisation's agreement rule alone (PoseAgreement): the first pose found is taken once enough
// further candidates put the frame within the step limits of it; one candidate elsewhere makes the
// frame ambiguous whatever came before; with the candidates run out, an uncontradicted first pose is
// taken.
#include <gtest/gtest.h>

#include <numbers>

#include "stillpoint/tracking/pose_agreement.hpp"

namespace sp::track {
namespace {

using Verdict = PoseAgreement::Verdict;

// The camera centre at (x, 0, 0), turned by yaw_deg about y.
geo::SE3 pose_at(double x, double yaw_deg = 0) {
  const Eigen::Quaterniond q(Eigen::AngleAxisd(yaw_deg * std::numbers::pi / 180.0, Eigen::Vector3d::UnitY()));
  const geo::SE3 T_wc(q, Eigen::Vector3d(x, 0, 0));
  return T_wc.inverse();
}

TEST(PoseAgreement, TheFirstPoseWaitsForTheNeededAgreeingCandidates) {
  PoseAgreement a(2, 0.05, 5.0);
  EXPECT_EQ(a.add(pose_at(0.30)), Verdict::Undecided);
  EXPECT_EQ(a.add(pose_at(0.32, 1.0)), Verdict::Undecided);  // 2 cm, 1 deg: agrees
  EXPECT_EQ(a.add(pose_at(0.27)), Verdict::Agreed);
  EXPECT_EQ(a.add(pose_at(0.90)), Verdict::Agreed);  // decided: later poses change nothing
}

TEST(PoseAgreement, OneCandidateElsewhereMakesTheFrameAmbiguous) {
  PoseAgreement a(3, 0.05, 5.0);
  EXPECT_EQ(a.add(pose_at(0.30)), Verdict::Undecided);
  EXPECT_EQ(a.add(pose_at(0.31)), Verdict::Undecided);
  EXPECT_EQ(a.add(pose_at(0.75)), Verdict::Ambiguous);  // 45 cm away, as a repeated wall texture gives
  EXPECT_NEAR(a.conflict().translation_m, 0.45, 1e-9);
  EXPECT_EQ(a.add(pose_at(0.30)), Verdict::Ambiguous);
  EXPECT_EQ(a.finish(), Verdict::Ambiguous);
}

TEST(PoseAgreement, ATurnBeyondTheLimitIsElsewhereToo) {
  PoseAgreement a(1, 0.05, 5.0);
  a.add(pose_at(0.30));
  EXPECT_EQ(a.add(pose_at(0.30, 6.0)), Verdict::Ambiguous);
  EXPECT_NEAR(a.conflict().rotation_deg, 6.0, 1e-6);
}

TEST(PoseAgreement, WhenTheCandidatesRunOutAnUncontradictedPoseIsTaken) {
  PoseAgreement a(2, 0.05, 5.0);
  EXPECT_EQ(a.finish(), Verdict::Undecided);  // nothing found
  a.add(pose_at(0.30));
  EXPECT_EQ(a.finish(), Verdict::Agreed);
}

TEST(PoseAgreement, NoneNeededTakesTheFirstPoseAtOnce) {
  PoseAgreement a(0, 0.05, 5.0);
  EXPECT_EQ(a.add(pose_at(0.30)), Verdict::Agreed);
}

}  // namespace
}  // namespace sp::track
