#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>

#include "stillpoint/tracking/keyframe_policy.hpp"

namespace sp::track {
namespace {

Eigen::Matrix3i grid(std::initializer_list<int> v) {
  Eigen::Matrix3i m;
  auto it = v.begin();
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) m(i, j) = *it++;
  }
  return m;
}

TEST(GridBalance, EmptyGridIsNotSpread) {
  const auto b = grid_balance(Eigen::Matrix3i::Zero());
  EXPECT_DOUBLE_EQ(b.t1, 0.0);
  EXPECT_DOUBLE_EQ(b.t2, 0.0);
  EXPECT_FALSE(b.spread_out());
}

TEST(GridBalance, SingleCornerCell) {
  // Centre of gravity at cell (1,1) (1-based) -> T1 = |(1,1) - (2,2)| = sqrt(2); no second cell -> T2 = 0.
  const auto b = grid_balance(grid({10, 0, 0, 0, 0, 0, 0, 0, 0}));
  EXPECT_NEAR(b.t1, std::sqrt(2.0), 1e-12);
  EXPECT_DOUBLE_EQ(b.t2, 0.0);
  EXPECT_FALSE(b.spread_out());
}

TEST(GridBalance, OppositeCornersAreSpread) {
  // Balanced mass -> T1 = 0; equal cells two diagonal steps apart -> T2 = 1 * sqrt(8).
  const auto b = grid_balance(grid({10, 0, 0, 0, 0, 0, 0, 0, 10}));
  EXPECT_NEAR(b.t1, 0.0, 1e-12);
  EXPECT_NEAR(b.t2, std::sqrt(8.0), 1e-12);
  EXPECT_TRUE(b.spread_out());
}

TEST(GridBalance, LeftColumnPairIsNotSpread) {
  // Cells (1,1) and (2,1): centre of gravity (x=1, y=1.5) -> T1 = sqrt(1 + 0.25); T2 = 1 * 1.
  const auto b = grid_balance(grid({10, 0, 0, 10, 0, 0, 0, 0, 0}));
  EXPECT_NEAR(b.t1, std::sqrt(1.25), 1e-12);
  EXPECT_NEAR(b.t2, 1.0, 1e-12);
  EXPECT_FALSE(b.spread_out());
}

TEST(GridBalance, WeakSecondCellDoesNotCount) {
  // (1,1)=10, (3,3)=2: x = y = (10 + 3*2)/12 -> T1 = sqrt(2) * (2 - 16/12); T2 = 0.2 * sqrt(8).
  const auto b = grid_balance(grid({10, 0, 0, 0, 0, 0, 0, 0, 2}));
  EXPECT_NEAR(b.t1, std::sqrt(2.0) * (2.0 - 16.0 / 12.0), 1e-12);
  EXPECT_NEAR(b.t2, 0.2 * std::sqrt(8.0), 1e-12);
  EXPECT_FALSE(b.spread_out());
}

TEST(GridBalance, UniformGridIsSpread) {
  const auto b = grid_balance(grid({5, 5, 5, 5, 5, 5, 5, 5, 5}));
  EXPECT_NEAR(b.t1, 0.0, 1e-12);
  EXPECT_NEAR(b.t2, 1.0, 1e-12);  // two largest (ties in row-major order) are neighbours
  EXPECT_TRUE(b.spread_out());
}

TEST(ViewingAngle, MatchesKnownRotationAboutThePoint) {
  const Eigen::Vector3d p(0.3, -0.2, 2.0);
  const Eigen::Vector3d c_ref(0.0, 0.0, 0.0);
  for (double deg : {0.5, 25.0, 30.0, 35.0, 120.0}) {
    // Rotating the camera centre about an axis through the point, perpendicular to the ray, turns
    // the ray by exactly `deg`; moving the camera along the new ray must not change the angle.
    const Eigen::Vector3d ray = c_ref - p;
    const Eigen::Vector3d axis = ray.cross(Eigen::Vector3d(0.2, 1.0, 0.1)).normalized();
    const Eigen::AngleAxisd rot(deg * M_PI / 180.0, axis);
    const Eigen::Vector3d c_now = p + rot * ray * 1.7;
    EXPECT_NEAR(viewing_angle_change_deg(p, c_ref, c_now), deg, 1e-9);
  }
}

TEST(EffectiveGrid, CountsOnlyPointsBeyondThe30DegreeRule) {
  std::vector<ViewChange> changes = {
      {10, 10, 31.0f},    // top-left, effective
      {630, 470, 45.0f},  // bottom-right, effective
      {320, 240, 29.9f},  // centre, not effective
      {320, 240, 30.0f},  // exactly 30 is not "more than 30"
      {639, 0, 90.0f},    // top-right, effective
  };
  const Eigen::Matrix3i g = effective_point_grid(changes, 640, 480, 30.0);
  EXPECT_EQ(g.sum(), 3);
  EXPECT_EQ(g(0, 0), 1);
  EXPECT_EQ(g(2, 2), 1);
  EXPECT_EQ(g(0, 2), 1);
  EXPECT_EQ(g(1, 1), 0);
}

KeyframeCandidate healthy_candidate() {
  KeyframeCandidate c;
  c.frames_since_keyframe = 5;
  c.tracked_inliers = 300;
  c.reference_tracked = 350;
  c.close_tracked = 250;
  c.close_untracked = 20;
  c.keyframes_in_map = 10;
  c.mapping_idle = true;
  return c;
}

TEST(HeuristicPolicy, InsertsWhenLosingTheReference) {
  KeyframePolicyConfig cfg;
  auto policy = make_keyframe_policy(cfg);
  KeyframeCandidate c = healthy_candidate();
  EXPECT_FALSE(policy->decide(c));  // tracking well: no keyframe
  c.tracked_inliers = 200;          // < 0.75 * 350
  EXPECT_TRUE(policy->decide(c));
  c.mapping_idle = false;
  c.mapping_queue = 3;  // local mapping swamped
  EXPECT_FALSE(policy->decide(c));
}

TEST(AdaptivePolicy, NeedsManySpreadEffectivePoints) {
  KeyframePolicyConfig cfg;
  cfg.policy = "adaptive";
  auto policy = make_keyframe_policy(cfg);
  ASSERT_TRUE(policy->needs_view_changes());
  KeyframeCandidate c = healthy_candidate();
  // 300 tracked inliers -> threshold 0.25 * 300 = 75 effective points.
  for (int i = 0; i < 80; ++i) c.view_changes.push_back({20.0f, 20.0f, 40.0f});  // all in one corner
  EXPECT_FALSE(policy->decide(c));
  c.view_changes.clear();
  for (int i = 0; i < 40; ++i) c.view_changes.push_back({20.0f, 20.0f, 40.0f});
  for (int i = 0; i < 40; ++i) c.view_changes.push_back({620.0f, 460.0f, 40.0f});
  EXPECT_TRUE(policy->decide(c));  // 80 effective points in opposite corners
  c.view_changes.resize(60);       // 40 + 20: below the adaptive threshold of 75
  EXPECT_FALSE(policy->decide(c));
}

TEST(AdaptivePolicy, SafetyNetInsertsWhenCloseTrackedPointsRunOut) {
  KeyframePolicyConfig cfg;
  cfg.policy = "adaptive";
  auto policy = make_keyframe_policy(cfg);
  KeyframeCandidate c = healthy_candidate();
  c.close_tracked = 50;
  c.close_untracked = 200;
  EXPECT_TRUE(policy->decide(c));
}

}  // namespace
}  // namespace sp::track
