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

// Eqs. 2-5 on hand-computed inputs. Cells are 1-based (row i, column j); x = Σ j·M_ij / ΣM, y = Σ i·M_ij /
// ΣM; T1 = |(x, y) − (2, 2)| (Eq. 4 with the origin at the centre cell, docs/keyframe_policy.md); T2 =
// dist(p1, p2) · M2 / (2√2 · M1) (Eq. 5 as printed). 2√2 = 2.8284271247.

TEST(GridBalance, EmptyGridIsNotSpread) {
  const auto b = grid_balance(Eigen::Matrix3i::Zero());
  EXPECT_DOUBLE_EQ(b.t1, 0.0);
  EXPECT_DOUBLE_EQ(b.t2, 0.0);
  EXPECT_FALSE(b.spread_out());
}

TEST(GridBalance, SingleCornerCell) {
  // (x, y) = (1, 1) -> T1 = |(-1, -1)| = 1.41421356; no second cell (M2 = 0) -> T2 = 0.
  const auto b = grid_balance(grid({10, 0, 0, 0, 0, 0, 0, 0, 0}));
  EXPECT_NEAR(b.t1, 1.4142135624, 1e-9);
  EXPECT_DOUBLE_EQ(b.t2, 0.0);
  EXPECT_FALSE(b.spread_out());
}

TEST(GridBalance, OppositeCornersAreSpread) {
  // (x, y) = (2, 2) -> T1 = 0; p1 = (1,1), p2 = (3,3): dist = 2√2, M2/M1 = 1 -> T2 = 2√2 / 2√2 = 1 (the
  // maximum).
  const auto b = grid_balance(grid({10, 0, 0, 0, 0, 0, 0, 0, 10}));
  EXPECT_NEAR(b.t1, 0.0, 1e-12);
  EXPECT_NEAR(b.t2, 1.0, 1e-12);
  EXPECT_TRUE(b.spread_out());
}

TEST(GridBalance, LeftColumnPairIsNotSpread) {
  // (1,1) = (2,1) = 10: x = 1, y = 1.5 -> T1 = |(-1, -0.5)| = 1.11803399; dist = 1 -> T2 = 1 / 2.82842712 =
  // 0.35355339.
  const auto b = grid_balance(grid({10, 0, 0, 10, 0, 0, 0, 0, 0}));
  EXPECT_NEAR(b.t1, 1.1180339887, 1e-9);
  EXPECT_NEAR(b.t2, 0.3535533906, 1e-9);
  EXPECT_FALSE(b.spread_out());
}

TEST(GridBalance, WeakSecondCellDoesNotCount) {
  // (1,1) = 10, (3,3) = 2: x = y = (10 + 3·2) / 12 = 4/3 -> T1 = √2 · 2/3 = 0.94280904;
  // T2 = 2√2 · 0.2 / 2√2 = 0.2.
  const auto b = grid_balance(grid({10, 0, 0, 0, 0, 0, 0, 0, 2}));
  EXPECT_NEAR(b.t1, 0.9428090416, 1e-9);
  EXPECT_NEAR(b.t2, 0.2, 1e-12);
  EXPECT_FALSE(b.spread_out());
}

TEST(GridBalance, UniformGridIsSpread) {
  // T1 = 0; the two largest (ties in row-major order) are (1,1) and (1,2): T2 = 1 / 2√2 = 0.35355339.
  const auto b = grid_balance(grid({5, 5, 5, 5, 5, 5, 5, 5, 5}));
  EXPECT_NEAR(b.t1, 0.0, 1e-12);
  EXPECT_NEAR(b.t2, 0.3535533906, 1e-9);
  EXPECT_TRUE(b.spread_out());
}

TEST(GridBalance, TheNormalisationDecides) {
  // Top row, (1,1) = 10 and (1,3) = 6: x = (10 + 3·6) / 16 = 1.75, y = 1 -> T1 = |(-0.25, -1)| = 1.03077641;
  // dist = 2, M2/M1 = 0.6 -> T2 = 1.2 / 2.82842712 = 0.42426407 < T1: not spread (without the 2√2, 1.2 > T1).
  const auto top = grid_balance(grid({10, 0, 6, 0, 0, 0, 0, 0, 0}));
  EXPECT_NEAR(top.t1, 1.0307764064, 1e-9);
  EXPECT_NEAR(top.t2, 0.4242640687, 1e-9);
  EXPECT_FALSE(top.spread_out());
  // Middle row, (2,1) = 10 and (2,3) = 6: x = 1.75, y = 2 -> T1 = 0.25; T2 = 0.42426407 > T1: spread.
  const auto middle = grid_balance(grid({0, 0, 0, 10, 0, 6, 0, 0, 0}));
  EXPECT_NEAR(middle.t1, 0.25, 1e-12);
  EXPECT_NEAR(middle.t2, 0.4242640687, 1e-9);
  EXPECT_TRUE(middle.spread_out());
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

TEST(ViewingAngle, FromTheMeanViewingDirection) {
  // Two keyframes seeing the point from +-20 deg about the z axis: the mean direction is the z axis,
  // so a camera on that axis has changed nothing, one rotated 50 deg about the point has changed 50.
  const Eigen::Vector3d p(0.0, 0.0, 3.0);
  const auto centre_at = [&](double deg) {
    return Eigen::Vector3d(p + Eigen::AngleAxisd(deg * M_PI / 180.0, Eigen::Vector3d::UnitY()) *
                                   Eigen::Vector3d(0.0, 0.0, -3.0));
  };
  const Eigen::Vector3d normal =
      ((p - centre_at(20.0)).normalized() + (p - centre_at(-20.0)).normalized()).normalized();
  EXPECT_NEAR(angle_from_normal_deg(p, normal, centre_at(0.0)), 0.0, 1e-9);
  EXPECT_NEAR(angle_from_normal_deg(p, normal, centre_at(50.0)), 50.0, 1e-9);
  // Against the first keyframe alone the same camera changed 30 deg: the readings differ.
  EXPECT_NEAR(viewing_angle_change_deg(p, centre_at(20.0), centre_at(50.0)), 30.0, 1e-9);
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

// How often `rule` fired in the policy's counts; -1 when the policy has no such rule.
long rule_count(const KeyframePolicy& policy, const std::string& rule) {
  for (const auto& [name, n] : policy.rule_counts()) {
    if (name == rule) return static_cast<long>(n);
  }
  return -1L;
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
  // Rule counts: 3 decisions; the corner frame met the threshold but was not spread; one inserted by
  // the paper's rule; no safety net fired.
  const auto count = [&](const std::string& rule) { return rule_count(*policy, rule); };
  EXPECT_EQ(count("decisions"), 3);
  EXPECT_EQ(count("any_effective"), 3);
  EXPECT_EQ(count("threshold_met"), 2);
  EXPECT_EQ(count("threshold_met_not_spread"), 1);
  EXPECT_EQ(count("effective_spread"), 1);
  EXPECT_EQ(count("inserted"), 1);
  EXPECT_EQ(count("close_points"), 0);
  EXPECT_EQ(count("weak_tracking"), 0);
  EXPECT_EQ(count("reference_fallback"), 0);
  EXPECT_EQ(count("vetoed_weak"), 0);
}

TEST(AdaptivePolicy, CountsTheRuleThatDecided) {
  KeyframePolicyConfig cfg;
  cfg.policy = "adaptive";
  auto policy = make_keyframe_policy(cfg);
  KeyframeCandidate c = healthy_candidate();
  c.tracked_inliers = 10;  // <= min_inliers 15: vetoed
  EXPECT_FALSE(policy->decide(c));
  c = healthy_candidate();
  c.tracked_inliers = 80;  // < 0.25 * 350: tracking weak
  EXPECT_TRUE(policy->decide(c));
  c = healthy_candidate();
  c.tracked_inliers = 200;  // < 0.75 * 350 with mapping idle, no effective points: the fallback
  EXPECT_TRUE(policy->decide(c));
  c.mapping_idle = false;
  c.mapping_queue = 5;  // swamped
  EXPECT_FALSE(policy->decide(c));
  const KeyframeRuleCounts expected = {
      {"decisions", 4},           {"vetoed_weak", 1},        {"vetoed_swamped", 1},
      {"vetoed_at_reference", 0}, {"close_points", 0},       {"weak_tracking", 1},
      {"any_effective", 0},       {"threshold_met", 0},      {"threshold_met_not_spread", 0},
      {"effective_spread", 0},    {"reference_fallback", 1}, {"inserted", 2}};
  EXPECT_EQ(policy->rule_counts(), expected);
}

TEST(HeuristicPolicy, CountsInsertionsAndTheirConditions) {
  auto policy = make_keyframe_policy(KeyframePolicyConfig{});
  KeyframeCandidate c = healthy_candidate();
  EXPECT_FALSE(policy->decide(c));
  c.tracked_inliers = 200;
  EXPECT_TRUE(policy->decide(c));  // mapping idle and losing the reference
  const KeyframeRuleCounts expected = {{"decisions", 2},
                                       {"vetoed_weak", 0},
                                       {"vetoed_swamped", 0},
                                       {"vetoed_at_reference", 0},
                                       {"inserted", 1},
                                       {"inserted_timed_out", 0},
                                       {"inserted_mapping_idle", 1},
                                       {"inserted_weak_or_close", 0}};
  EXPECT_EQ(policy->rule_counts(), expected);
}

// A camera still at its reference keyframe's place makes no keyframe while it tracks enough inliers,
// whatever rule would have fired; one step outside either distance, or below the inlier count, the
// rules decide again.
TEST(KeyframePolicies, HoldWhileAtTheReferenceKeyframesPlace) {
  for (const std::string name : {"adaptive", "heuristic"}) {
    SCOPED_TRACE(name);
    KeyframePolicyConfig cfg;
    cfg.policy = name;
    cfg.hold_min_tracked = 100;
    cfg.hold_max_translation_m = 0.02;
    cfg.hold_max_rotation_deg = 1.0;
    auto policy = make_keyframe_policy(cfg);
    // 200 inliers < 0.75 * 350 with mapping idle: both policies insert unless held.
    const auto at = [](double translation_m, double rotation_deg, int inliers = 200) {
      KeyframeCandidate c = healthy_candidate();
      c.tracked_inliers = inliers;
      c.reference_translation_m = translation_m;
      c.reference_rotation_deg = rotation_deg;
      return c;
    };
    KeyframeCandidate unknown = healthy_candidate();
    unknown.tracked_inliers = 200;
    ASSERT_TRUE(policy->decide(unknown)) << "place unknown: never held";
    EXPECT_FALSE(policy->decide(at(0.019, 0.9))) << "at the reference's place";
    KeyframeCandidate close_running_out = at(0.019, 0.9);
    close_running_out.close_tracked = 50;
    close_running_out.close_untracked = 200;
    EXPECT_FALSE(policy->decide(close_running_out)) << "held even when close points run out";
    EXPECT_TRUE(policy->decide(at(0.021, 0.0))) << "2.1 cm away";
    EXPECT_TRUE(policy->decide(at(0.0, 1.1))) << "turned 1.1 deg";
    EXPECT_TRUE(policy->decide(at(0.0, 0.0, 99))) << "tracking fewer than hold_min_tracked";
    EXPECT_EQ(rule_count(*policy, "vetoed_at_reference"), 2);
    KeyframePolicyConfig off = cfg;
    off.hold_min_tracked = 0;
    EXPECT_TRUE(make_keyframe_policy(off)->decide(at(0.0, 0.0))) << "hold_min_tracked 0: never held";
  }
}

TEST(KeyframePolicyConfig, HoldKeysAreReadAndRangeChecked) {
  const KeyframePolicyConfig c = KeyframePolicyConfig::from_yaml(ConfigReader::from_string(
      "policy: adaptive\nhold_min_tracked: 120\nhold_max_translation_m: 0.01\nhold_max_rotation_deg: 0.5\n",
      "keyframes.yaml"));
  EXPECT_EQ(c.hold_min_tracked, 120);
  EXPECT_DOUBLE_EQ(c.hold_max_translation_m, 0.01);
  EXPECT_DOUBLE_EQ(c.hold_max_rotation_deg, 0.5);
  EXPECT_THROW(KeyframePolicyConfig::from_yaml(ConfigReader::from_string("hold_min_tracked: -1\n", "k.yaml")),
               std::exception);
  EXPECT_THROW(
      KeyframePolicyConfig::from_yaml(ConfigReader::from_string("hold_max_rotation_deg: 90\n", "k.yaml")),
      std::exception);
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
