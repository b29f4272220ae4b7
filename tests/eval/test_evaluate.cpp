#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "stillpoint/common/error.hpp"
#include "stillpoint/eval/evaluate.hpp"

namespace sp::eval {
namespace {

using io::StampedPose;
constexpr double kDeg = M_PI / 180.0;

StampedPose pose(double stamp, const Eigen::Vector3d& t,
                 const Eigen::Quaterniond& q = Eigen::Quaterniond::Identity()) {
  return {stamp, t, q};
}

Eigen::Quaterniond yaw(double rad) {
  return Eigen::Quaterniond(Eigen::AngleAxisd(rad, Eigen::Vector3d::UnitZ()));
}

// A wavy 3-D trajectory at 30 Hz with turning orientation.
std::vector<StampedPose> wavy(int n) {
  std::vector<StampedPose> out;
  for (int k = 0; k < n; ++k) {
    const double t = k / 30.0;
    out.push_back(
        pose(100.0 + t, {std::cos(t), 0.5 * std::sin(2 * t), 0.2 * std::sin(0.7 * t) + 0.1 * t},
             yaw(0.3 * t) * Eigen::Quaterniond(Eigen::AngleAxisd(0.1 * t, Eigen::Vector3d::UnitX()))));
  }
  return out;
}

TEST(Evaluate, AlignmentRecoversRandomSe3AndSim3) {
  std::mt19937 rng(17);
  for (Alignment align : {Alignment::SE3, Alignment::Sim3}) {
    const auto gt = wavy(120);
    const Eigen::Quaterniond Rq = Eigen::Quaterniond::UnitRandom();
    const Eigen::Vector3d t(0.7, -2.0, 1.1);
    const double s = align == Alignment::Sim3 ? 0.37 : 1.0;
    // est = S^-1 gt: aligning est onto gt must give S back.
    std::vector<StampedPose> est;
    for (const auto& p : gt) est.push_back(pose(p.stamp, Rq.inverse() * (p.t - t) / s, Rq.inverse() * p.q));
    EvalOptions o;
    o.align = align;
    const auto r = evaluate(gt, est, o);
    EXPECT_EQ(r.pairs, 120u);
    EXPECT_LT((r.alignment.R - Rq.toRotationMatrix()).norm(), 1e-9);
    EXPECT_LT((r.alignment.t - t).norm(), 1e-9);
    EXPECT_NEAR(r.alignment.scale, s, 1e-9);
    EXPECT_LT(r.ate.max, 1e-9);
    // RPE uses the fitted scale, so the scaled copy has no relative error either.
    EXPECT_LT(r.rpe_trans.max, 1e-9);
    EXPECT_LT(r.rpe_rot_deg.max, 1e-5);  // acos near 1 amplifies rounding
  }
}

TEST(Evaluate, AteOfAKnownOffsetPatternUnderSe3) {
  // Planar circle of 2N points; the estimate leaves the plane by +d, -d alternately. The pattern sums to
  // zero and is orthogonal to the positions, so the best alignment is the true one and every error is d.
  const int n2 = 40;
  const double d = 0.03;
  const Eigen::Quaterniond Rq(Eigen::AngleAxisd(0.8, Eigen::Vector3d(1, 2, 3).normalized()));
  const Eigen::Vector3d t(3, -1, 0.5);
  std::vector<StampedPose> gt, est;
  for (int k = 0; k < n2; ++k) {
    const double a = 2 * M_PI * k / n2;
    const Eigen::Vector3d p(2 * std::cos(a), 2 * std::sin(a), 0);
    gt.push_back(pose(k * 0.1, Rq * p + t));
    est.push_back(pose(k * 0.1 + 0.005, p + Eigen::Vector3d(0, 0, k % 2 ? -d : d)));
  }
  const auto r = evaluate(gt, est, {});
  EXPECT_EQ(r.pairs, static_cast<std::size_t>(n2));
  EXPECT_NEAR(r.ate.rmse, d, 1e-12);
  EXPECT_NEAR(r.ate.min, d, 1e-12);
  EXPECT_NEAR(r.ate.max, d, 1e-12);
  EXPECT_NEAR(r.ate.std, 0.0, 1e-12);
  EXPECT_LT((r.alignment.R - Rq.toRotationMatrix()).norm(), 1e-12);
}

TEST(Evaluate, RpeOfAConstantTranslationDrift) {
  // Ground truth moves along x at 1 m/s, the estimate at 1.01 m/s: over 1 s it is 0.01 m off.
  std::vector<StampedPose> gt, est;
  for (int k = 0; k < 100; ++k) {
    const double t = k / 30.0;
    gt.push_back(pose(t, {t, 0, 0}));
    est.push_back(pose(t, {1.01 * t, 0, 0}));
  }
  for (DeltaUnit unit : {DeltaUnit::Seconds, DeltaUnit::Frames}) {
    EvalOptions o;
    o.delta_unit = unit;
    o.delta = unit == DeltaUnit::Seconds ? 1.0 : 30.0;
    const auto r = evaluate(gt, est, o);
    // i + 30 must stay below the last index 99: i = 0..68.
    EXPECT_EQ(r.rpe_pairs, 69u);
    EXPECT_NEAR(r.rpe_trans.min, 0.01, 1e-9);
    EXPECT_NEAR(r.rpe_trans.max, 0.01, 1e-9);
    EXPECT_NEAR(r.rpe_rot_deg.max, 0.0, 1e-5);
  }
}

TEST(Evaluate, RpeOfAConstantRotationDrift) {
  // Ground truth stands still; the estimate turns at 2 deg/s about z: 2 deg per 1 s, 1 deg per 15 frames.
  std::vector<StampedPose> gt, est;
  for (int k = 0; k < 90; ++k) {
    const double t = 5.0 + k / 30.0;
    gt.push_back(pose(t, {1, 2, 3}));
    est.push_back(pose(t, {0, 0, 0}, yaw(2 * kDeg * (t - 5.0))));
  }
  EvalOptions o;
  o.align = Alignment::None;
  const auto r = evaluate(gt, est, o);
  EXPECT_EQ(r.rpe_pairs, 59u);
  EXPECT_NEAR(r.rpe_rot_deg.min, 2.0, 1e-9);
  EXPECT_NEAR(r.rpe_rot_deg.max, 2.0, 1e-9);
  EXPECT_NEAR(r.rpe_trans.max, 0.0, 1e-12);
  EXPECT_NEAR(r.ate.mean, std::sqrt(14.0), 1e-12);  // no alignment: |(1,2,3)|
  o.delta = 15;
  o.delta_unit = DeltaUnit::Frames;
  EXPECT_NEAR(evaluate(gt, est, o).rpe_rot_deg.rmse, 1.0, 1e-9);
}

// Ten poses at 1 Hz along x; the estimate is off sideways by e_k and, at pose 8, turned by 10 degrees.
TEST(Evaluate, TenPoseExampleWorkedByHand) {
  const double e[10] = {0, 0, 0.1, 0.1, 0.3, 0.3, 0, 0, 0.2, 0.2};
  const double th = 10 * kDeg;
  std::vector<StampedPose> gt, est;
  for (int k = 0; k < 10; ++k) {
    gt.push_back(pose(k, {double(k), 0, 0}));
    est.push_back(pose(k, {double(k), e[k], 0}, k == 8 ? yaw(th) : Eigen::Quaterniond::Identity()));
  }
  EvalOptions o;
  o.align = Alignment::None;
  const auto r = evaluate(gt, est, o);
  // ATE = |e_k|: sum 1.2, sum of squares 0.28, sorted middle values 0.1 and 0.1.
  EXPECT_EQ(r.pairs, 10u);
  EXPECT_NEAR(r.ate.mean, 0.12, 1e-12);
  EXPECT_NEAR(r.ate.rmse, std::sqrt(0.028), 1e-12);
  EXPECT_NEAR(r.ate.median, 0.1, 1e-12);
  EXPECT_NEAR(r.ate.std, std::sqrt(0.028 - 0.0144), 1e-12);
  EXPECT_NEAR(r.ate.max, 0.3, 1e-12);
  // RPE, delta 1 s: pairs (i, i+1) for i = 0..7 (j = 9 is the last estimate). With identity rotations the
  // error is |e_{i+1} - e_i|: 0, 0.1, 0, 0.2, 0, 0.3, 0, and for (7, 8), where P_8 is turned by th:
  // E = [R(th), (1, 0.2, 0)] [I, (-1, 0, 0)] -> t(E) = (1 - cos th, 0.2 - sin th, 0), angle th.
  const double c = std::hypot(1 - std::cos(th), 0.2 - std::sin(th));
  EXPECT_EQ(r.rpe_pairs, 8u);
  EXPECT_NEAR(r.rpe_trans.mean, (0.6 + c) / 8, 1e-12);
  EXPECT_NEAR(r.rpe_trans.rmse, std::sqrt((0.01 + 0.04 + 0.09 + c * c) / 8), 1e-12);
  EXPECT_NEAR(r.rpe_trans.median, c / 2, 1e-12);  // sorted: 0 0 0 0 c 0.1 0.2 0.3
  EXPECT_NEAR(r.rpe_trans.max, 0.3, 1e-12);
  EXPECT_NEAR(r.rpe_rot_deg.mean, 10.0 / 8, 1e-9);
  EXPECT_NEAR(r.rpe_rot_deg.rmse, std::sqrt(100.0 / 8), 1e-9);
  EXPECT_NEAR(r.rpe_rot_deg.median, 0.0, 1e-9);
  EXPECT_NEAR(r.rpe_rot_deg.max, 10.0, 1e-9);
}

TEST(Evaluate, RpeDropsPairsWhoseGroundTruthIsTooFar) {
  // Ground truth at 10 Hz with a hole between 1.9 s and 4.1 s; estimates at 10 Hz, 0.03 s later. The
  // median ground-truth step is 0.1 s, so an estimate needs ground truth within 0.2 s: estimates k = 21
  // (2.13 s, 0.23 s from 1.9) to 38 (3.83 s, 0.27 s from 4.1) have none; 20 (0.13 s) and 39 (0.17 s) do.
  std::vector<StampedPose> gt, est;
  for (int m = 0; m <= 61; ++m) {
    if (m <= 19 || m >= 41) gt.push_back(pose(m * 0.1, {m * 0.1, 0, 0}));
  }
  for (int k = 0; k <= 60; ++k) est.push_back(pose(k * 0.1 + 0.03, {k * 0.1, 0, 0}));
  EvalOptions o;
  o.align = Alignment::None;
  o.max_difference = 0.05;
  o.delta = 0.5;
  const auto r = evaluate(gt, est, o);
  // Pairs (i, i + 5) for i = 0..54; dropped when i or i + 5 lies in 21..38, i.e. i in 16..38: 55 - 23.
  EXPECT_EQ(r.rpe_pairs, 32u);
  // Kept pairs next to the hole use ground truth up to 0.17 s away: worst is (39, 44), estimate 3.9 ->
  // 4.4 m but ground truth 4.1 (at 4.1 s) -> 4.4 m, 0.2 m apart.
  EXPECT_NEAR(r.rpe_trans.max, 0.2, 1e-9);
}

TEST(Evaluate, NoOverlapThrows) {
  const auto gt = wavy(30);
  auto est = gt;
  for (auto& p : est) p.stamp += 100.0;
  EXPECT_THROW((void)evaluate(gt, est, {}), Error);
  EvalOptions o;
  o.offset = -100.0;  // the offset brings them back together
  EXPECT_EQ(evaluate(gt, est, o).pairs, 30u);
}

TEST(Evaluate, AteSplitIntoTheGroundTruthCamerasAxes) {
  // The estimate is off by d along each ground-truth camera's own optical axis (alternating sign) and by
  // e along its x axis; the cameras turn, so in the world frame the errors point everywhere.
  const double d = 0.02, e = 0.005;
  const auto gt = wavy(60);
  std::vector<StampedPose> est;
  for (std::size_t k = 0; k < gt.size(); ++k) {
    const double s = k % 2 ? -1.0 : 1.0;
    est.push_back(pose(gt[k].stamp, gt[k].t + gt[k].q * Eigen::Vector3d(e, 0, s * d), gt[k].q));
  }
  EvalOptions none;
  none.align = Alignment::None;
  const auto r = evaluate(gt, est, none);
  EXPECT_NEAR(r.ate_camera_axes_rmse.x(), e, 1e-12);
  EXPECT_NEAR(r.ate_camera_axes_rmse.y(), 0.0, 1e-12);
  EXPECT_NEAR(r.ate_camera_axes_rmse.z(), d, 1e-12);
  // With an alignment the split still adds up to the ATE.
  const auto aligned = evaluate(gt, est, {});
  EXPECT_NEAR(aligned.ate_camera_axes_rmse.squaredNorm(), aligned.ate.rmse * aligned.ate.rmse, 1e-12);
  EXPECT_GT(aligned.ate_camera_axes_rmse.z(), 2 * aligned.ate_camera_axes_rmse.y());
}

TEST(Evaluate, JsonAndTableCarryTheFigures) {
  const auto r = evaluate(wavy(90), wavy(90), {});
  const auto j = to_json(r);
  EXPECT_EQ(j.at("pairs").get<std::size_t>(), 90u);
  for (const char* key : {"ate", "rpe_trans", "rpe_rot_deg"}) {
    for (const char* f : {"rmse", "mean", "median", "std", "min", "max"}) EXPECT_TRUE(j.at(key).contains(f));
  }
  EXPECT_EQ(j.at("rpe_pairs").get<std::size_t>(), r.rpe_pairs);
  EXPECT_DOUBLE_EQ(j.at("ate").at("rmse").get<double>(), r.ate.rmse);
  const std::string table = format_table(r);
  EXPECT_NE(table.find("ATE"), std::string::npos);
  EXPECT_NE(table.find("RPE rot"), std::string::npos);
  EXPECT_NE(table.find("optical axis"), std::string::npos);
  EXPECT_DOUBLE_EQ(j.at("ate_camera_axes_rmse").at("z_optical_axis").get<double>(),
                   r.ate_camera_axes_rmse.z());
}

}  // namespace
}  // namespace sp::eval

namespace sp::eval {
namespace {

TEST(EvalOptions, FromYamlReadsChoicesAndRejectsUnknownValues) {
  const auto r =
      ConfigReader::from_string("align: sim3\ndelta: 30\ndelta_unit: f\noffset: 0.5\n", "eval.yaml");
  const auto o = EvalOptions::from_yaml(r);
  r.finish();
  EXPECT_EQ(o.align, Alignment::Sim3);
  EXPECT_EQ(o.delta_unit, DeltaUnit::Frames);
  EXPECT_DOUBLE_EQ(o.delta, 30.0);
  EXPECT_DOUBLE_EQ(o.offset, 0.5);
  EXPECT_DOUBLE_EQ(o.max_difference, 0.02);
  EXPECT_THROW((void)EvalOptions::from_yaml(ConfigReader::from_string("align: affine\n", "e.yaml")),
               ConfigError);
  EXPECT_THROW((void)EvalOptions::from_yaml(ConfigReader::from_string("delta: -1\n", "e.yaml")), ConfigError);
}

}  // namespace
}  // namespace sp::eval
