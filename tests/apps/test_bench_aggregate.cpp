// bench suite mode: medians over repeats, summaries per variant and group, the oracle ratio.
#include <gtest/gtest.h>

#include "bench_aggregate.hpp"

namespace sp::app::bench {
namespace {

RunMetrics run(const std::string& seq, const std::string& variant, int rep, std::optional<double> ate,
               std::optional<double> max_err, double lost, double fps, int exit_code = 0) {
  RunMetrics m;
  m.sequence = seq;
  m.variant = variant;
  m.repeat = rep;
  m.exit_code = exit_code;
  m.ate_cm = ate;
  m.max_error_cm = max_err;
  m.lost_frames = lost;
  m.fps = fps;
  return m;
}

const SummaryRow& find(const std::vector<SummaryRow>& rows, const std::string& group, const std::string& v) {
  for (const auto& r : rows) {
    if (r.group == group && r.variant == v) return r;
  }
  throw std::runtime_error("no summary row " + group + " / " + v);
}

TEST(BenchAggregate, MedianLikeNumpy) {
  EXPECT_FALSE(median({}).has_value());
  EXPECT_DOUBLE_EQ(*median({3.0}), 3.0);
  EXPECT_DOUBLE_EQ(*median({5.0, 1.0, 3.0}), 3.0);
  EXPECT_DOUBLE_EQ(*median({4.0, 1.0, 2.0, 10.0}), 3.0);  // mean of the two middle values
}

TEST(BenchAggregate, MediansAndSpreadOverRepeats) {
  const std::vector<RunMetrics> runs{
      run("tune/a", "default", 0, 2.0, 5.0, 0, 30.0), run("tune/a", "default", 1, 4.0, 9.0, 2, 20.0),
      run("tune/a", "default", 2, 3.0, 6.0, 1, 25.0), run("tune/a", "oracle", 0, 1.0, 2.0, 0, 40.0)};
  std::vector<RunMetrics> with_all = runs;
  with_all[0].ate_every_frame_cm = 7.0;  // one repeat lost frames, two have none filled (= their ATE)
  with_all[1].ate_every_frame_cm = 4.0;
  with_all[2].ate_every_frame_cm = 3.0;
  const auto rows = aggregate_repeats(with_all);
  ASSERT_EQ(rows.size(), 2u);
  const auto& d = rows[0];
  EXPECT_DOUBLE_EQ(*d.ate_every_frame_cm, 4.0);
  EXPECT_FALSE(rows[1].ate_every_frame_cm.has_value());
  EXPECT_EQ(d.sequence, "tune/a");
  EXPECT_EQ(d.variant, "default");
  EXPECT_EQ(d.runs, 3);
  EXPECT_EQ(d.failed, 0);
  EXPECT_DOUBLE_EQ(*d.ate_cm, 3.0);
  EXPECT_DOUBLE_EQ(*d.ate_min_cm, 2.0);
  EXPECT_DOUBLE_EQ(*d.ate_max_cm, 4.0);
  EXPECT_DOUBLE_EQ(*d.max_error_cm, 6.0);
  EXPECT_DOUBLE_EQ(*d.lost_frames, 1.0);
  EXPECT_DOUBLE_EQ(*d.fps, 25.0);
  EXPECT_FALSE(d.track_ms.has_value());
  EXPECT_EQ(rows[1].variant, "oracle");
  EXPECT_EQ(rows[1].runs, 1);
}

TEST(BenchAggregate, FailedRepeatsAreCountedAndLeftOutOfTheMedians) {
  RunMetrics crashed = run("s", "v", 1, std::nullopt, std::nullopt, 0, 0, 134);
  crashed.lost_frames.reset();  // a crashed run wrote no stats
  crashed.fps.reset();
  const auto rows =
      aggregate_repeats({run("s", "v", 0, 2.0, 3.0, 4, 10.0), crashed, run("s", "v", 2, 6.0, 7.0, 8, 30.0)});
  ASSERT_EQ(rows.size(), 1u);
  EXPECT_EQ(rows[0].runs, 3);
  EXPECT_EQ(rows[0].failed, 1);
  EXPECT_DOUBLE_EQ(*rows[0].ate_cm, 4.0);
  EXPECT_DOUBLE_EQ(*rows[0].lost_frames, 6.0);
  EXPECT_DOUBLE_EQ(*rows[0].fps, 20.0);
}

TEST(BenchAggregate, SummaryPerVariantWithOracleRatioAndGroups) {
  std::vector<AggregateRow> rows;
  auto add = [&](const std::string& seq, const std::string& v, std::optional<double> ate, double max_err,
                 double lost, double fps) {
    AggregateRow r;
    r.sequence = seq;
    r.variant = v;
    r.runs = 1;
    r.ate_cm = ate;
    r.max_error_cm = max_err;
    r.lost_frames = lost;
    r.fps = fps;
    rows.push_back(r);
  };
  add("tune/a", "default", 2.0, 5.0, 1, 30);
  add("tune/a", "cull:oracle", 1.0, 2.0, 0, 28);
  add("tune/b", "default", 6.0, 12.0, 3, 20);
  add("tune/b", "cull:oracle", 2.0, 4.0, 0, 22);
  add("heldout/c", "default", 4.0, 8.0, 0, 25);
  add("heldout/c", "cull:oracle", 4.0, 6.0, 2, 24);
  add("heldout/d", "default", std::nullopt, 0.0, 10, 5);  // no ATE (e.g. no ground truth)
  rows.back().max_error_cm.reset();

  const auto summary = summarize(rows, "cull:oracle");
  // all + tune + heldout (in order of appearance), two variants each.
  ASSERT_EQ(summary.size(), 6u);
  EXPECT_EQ(summary[0].group, "all");
  EXPECT_EQ(summary[2].group, "tune");
  EXPECT_EQ(summary[4].group, "heldout");

  const auto& all = find(summary, "all", "default");
  EXPECT_EQ(all.sequences, 4);
  EXPECT_EQ(all.with_ate, 3);
  EXPECT_DOUBLE_EQ(*all.ate_median_cm, 4.0);  // of 2, 6, 4
  EXPECT_DOUBLE_EQ(*all.ate_worst_cm, 6.0);
  EXPECT_DOUBLE_EQ(*all.max_error_worst_cm, 12.0);
  EXPECT_DOUBLE_EQ(all.lost_frames_total, 14.0);
  EXPECT_DOUBLE_EQ(*all.fps_median, 22.5);  // of 30, 20, 25, 5
  EXPECT_EQ(all.oracle_pairs, 3);           // ratios 2, 3, 1
  EXPECT_DOUBLE_EQ(*all.oracle_ratio_median, 2.0);
  EXPECT_DOUBLE_EQ(*all.oracle_ratio_worst, 3.0);

  const auto& tune = find(summary, "tune", "default");
  EXPECT_EQ(tune.sequences, 2);
  EXPECT_DOUBLE_EQ(*tune.ate_median_cm, 4.0);  // of 2, 6
  EXPECT_DOUBLE_EQ(*tune.oracle_ratio_median, 2.5);
  EXPECT_DOUBLE_EQ(*tune.oracle_ratio_worst, 3.0);
  EXPECT_DOUBLE_EQ(tune.lost_frames_total, 4.0);

  const auto& held = find(summary, "heldout", "default");
  EXPECT_EQ(held.sequences, 2);
  EXPECT_EQ(held.with_ate, 1);
  EXPECT_DOUBLE_EQ(*held.ate_worst_cm, 4.0);
  EXPECT_DOUBLE_EQ(*held.oracle_ratio_median, 1.0);

  const auto& oracle = find(summary, "all", "cull:oracle");
  EXPECT_DOUBLE_EQ(*oracle.oracle_ratio_worst, 1.0);
  EXPECT_DOUBLE_EQ(*oracle.ate_median_cm, 2.0);  // of 1, 2, 4
}

TEST(BenchAggregate, NoOracleNoRatioAndFlatSequencesOnlyAll) {
  std::vector<AggregateRow> rows(2);
  rows[0].sequence = "walking";
  rows[0].variant = "default";
  rows[0].ate_cm = 3.0;
  rows[0].failed = 2;
  rows[1].sequence = "static";
  rows[1].variant = "default";
  rows[1].ate_cm = 1.0;
  const auto summary = summarize(rows, "");
  ASSERT_EQ(summary.size(), 1u);
  EXPECT_EQ(summary[0].group, "all");
  EXPECT_EQ(summary[0].failed_runs, 2);
  EXPECT_DOUBLE_EQ(*summary[0].ate_median_cm, 2.0);
  EXPECT_FALSE(summary[0].oracle_ratio_median.has_value());
  EXPECT_EQ(summary[0].oracle_pairs, 0);
}

TEST(BenchAggregate, OracleVariantAndGroupDetection) {
  EXPECT_TRUE(is_oracle_variant("oracle", {}));
  EXPECT_TRUE(is_oracle_variant("cull:oracle", {"--dynamic", "oracle"}));
  EXPECT_TRUE(is_oracle_variant("gt-masks", {"--keyframe-policy", "adaptive", "--dynamic", "oracle"}));
  EXPECT_TRUE(is_oracle_variant("gt", {"--dynamic=oracle"}));
  EXPECT_FALSE(is_oracle_variant("cull:detector", {"--dynamic", "detector"}));
  EXPECT_FALSE(is_oracle_variant("oracle-free", {"--dynamic"}));
  EXPECT_EQ(sequence_group("tune/room101_walking_xyz"), "tune");
  EXPECT_EQ(sequence_group("heldout/x/y"), "heldout");
  EXPECT_EQ(sequence_group("office_a_walking_xyz"), "");
}

TEST(BenchAggregate, MetricsFromABenchRow) {
  const auto row = nlohmann::json::parse(R"({
    "sequence": "tune/room101", "variant": "default", "repeat": 2, "exit_code": 0,
    "frames": 50, "lost_frames": 3, "fps": 17.5,
    "ate": {"rmse": 0.0123, "max": 0.045}, "every_frame": {"ate_rmse_m": 0.0321},
    "ms": {"frame": {"median": 21.5, "p95": 30.0}, "track_lock": {"median": 0.75, "p95": 1.5}},
    "culling_score": {"true_dynamic_keypoints": 100, "precision": 0.8, "recall": 0.6}})");
  const RunMetrics m = metrics_from_row(row);
  EXPECT_EQ(m.sequence, "tune/room101");
  EXPECT_EQ(m.repeat, 2);
  EXPECT_NEAR(*m.ate_cm, 1.23, 1e-12);
  EXPECT_NEAR(*m.max_error_cm, 4.5, 1e-12);
  EXPECT_NEAR(*m.ate_every_frame_cm, 3.21, 1e-12);
  EXPECT_DOUBLE_EQ(*m.lost_frames, 3.0);
  EXPECT_DOUBLE_EQ(*m.fps, 17.5);
  EXPECT_DOUBLE_EQ(*m.track_ms, 21.5);
  EXPECT_DOUBLE_EQ(*m.lock_ms, 0.75);
  EXPECT_DOUBLE_EQ(*m.cull_precision, 0.8);
  EXPECT_DOUBLE_EQ(*m.cull_recall, 0.6);

  // A crashed run: no stats, so no zeros that look like measurements; no dynamic truth, no culling score.
  const auto crashed = metrics_from_row(nlohmann::json::parse(
      R"({"sequence": "s", "variant": "v", "exit_code": 139, "frames": 0, "lost_frames": 0, "fps": 0.0,
          "culling_score": {"true_dynamic_keypoints": 0, "precision": 0, "recall": 0}})"));
  EXPECT_EQ(crashed.exit_code, 139);
  EXPECT_FALSE(crashed.ate_cm.has_value());
  EXPECT_FALSE(crashed.ate_every_frame_cm.has_value());
  EXPECT_FALSE(crashed.lost_frames.has_value());
  EXPECT_FALSE(crashed.fps.has_value());
  EXPECT_FALSE(crashed.lock_ms.has_value());
  EXPECT_FALSE(crashed.cull_precision.has_value());
}

TEST(BenchAggregate, JsonKeepsEmptyMetricsAsNull) {
  AggregateRow r;
  r.sequence = "s";
  r.variant = "v";
  r.ate_cm = 1.5;
  const auto j = to_json(r);
  EXPECT_DOUBLE_EQ(j["ate_cm_median"].get<double>(), 1.5);
  EXPECT_TRUE(j["fps_median"].is_null());
}

TEST(PeerSpeed, FrameLoopWallWinsOverTheWholeBinary) {
  // run.sh's wall of the binary includes loading the vocabulary; the edited example's loop line does not.
  const std::string log =
      "[run] rgbd_tum rc=0 wall=18.0s\nloop wall: 15.5 s, with shutdown: 16.0 s\nmedian tracking time: "
      "0.0205\n";
  const PeerSpeed p = peer_speed(log, 400, 99.0);
  EXPECT_TRUE(p.frame_loop);
  EXPECT_DOUBLE_EQ(p.wall_s, 16.0);
  EXPECT_DOUBLE_EQ(p.fps, 25.0);
  ASSERT_TRUE(p.track_ms);
  EXPECT_NEAR(*p.track_ms, 20.5, 1e-9);
}

TEST(PeerSpeed, WithoutTheEditTheBinaryWallThenTheCallersWall) {
  const PeerSpeed binary = peer_speed("[run] rgbd_tum rc=0 wall=20.0s\n", 400, 99.0);
  EXPECT_FALSE(binary.frame_loop);
  EXPECT_DOUBLE_EQ(binary.fps, 20.0);
  EXPECT_FALSE(binary.track_ms);
  const PeerSpeed nothing = peer_speed("crashed\n", 400, 40.0);
  EXPECT_DOUBLE_EQ(nothing.wall_s, 40.0);
  EXPECT_DOUBLE_EQ(nothing.fps, 10.0);
  EXPECT_DOUBLE_EQ(peer_speed("", 400, 0.0).fps, 0.0);
}

}  // namespace
}  // namespace sp::app::bench
