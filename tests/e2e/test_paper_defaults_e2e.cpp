// End-to-end: the shipped configuration as it is (the paper's system: YOLOX-nano from models/ + flow
// culling, adaptive keyframes, keyframe-sequence loop detection with the rising-edge rule) on the short
// walking cut, in deterministic mode. Asserts that every part really ran, then an ATE bound.
#include <gtest/gtest.h>

#include <filesystem>

#include "../support/shared_data.hpp"
#include "stillpoint/api/runner.hpp"
#include "stillpoint/io/tum_sequence.hpp"

namespace sp::pipeline {
namespace {

using api::run_slam;  // stillpoint run's runner, on the public API
using api::RunOptions;
using api::RunResult;

const std::filesystem::path kSequence =
    std::filesystem::path(SP_SHARED_DIR) / "data" / "dynsynth" / "office_a_walking_xyz_150";
const std::filesystem::path kConfig = std::filesystem::path(SP_SOURCE_DIR) / "config" / "stillpoint.yaml";

TEST(PaperDefaults, WalkingCutRunsEveryPaperMethodWithinTheBound) {
  SP_REQUIRE_SHARED(kSequence);
  io::TumSequence source(kSequence);
  const SystemConfig config = SystemConfig::load(kConfig);  // nothing changed: the defaults are the test
  RunOptions options;
  options.out_dir = std::filesystem::path(SP_TEST_TMP_DIR) / "e2e" / "paper_defaults";
  std::filesystem::remove_all(options.out_dir);
  std::filesystem::create_directories(options.out_dir);
  options.deterministic = true;
  options.progress = false;
  options.groundtruth = source.groundtruth_path();
  options.boxes_file = kSequence / "boxes.txt";
  options.masks_dir = kSequence / "masks";
  options.project_root = SP_SOURCE_DIR;
  const RunResult r = run_slam(source, config, options);
  ASSERT_TRUE(r.completed);
  const auto& s = r.stats;

  // Culling: the shipped detector (resolved against the project root) and the motion check ran.
  EXPECT_EQ(s["dynamic_mode"].get<std::string>(), "detector+flow");
  EXPECT_EQ(std::filesystem::path(s["detector_model"].get<std::string>()),
            std::filesystem::path(SP_SOURCE_DIR) / "models" / "yolox_nano" / "yolox_nano.onnx");
  EXPECT_GT(s["stages_ms"]["detector"]["count"].get<int>(), 0);
  EXPECT_GT(s["culled_features_total"].get<int>(), 0);

  // Keyframes: the adaptive policy decided, and its rule counts add up.
  EXPECT_EQ(s["keyframe_policy"].get<std::string>(), "adaptive");
  const auto& rules = s["keyframe_rules"];
  const int decisions = rules["decisions"].get<int>();
  const int inserted = rules["inserted"].get<int>();
  EXPECT_GT(decisions, 0);
  EXPECT_LE(decisions, s["frames"].get<int>());
  EXPECT_GT(inserted, 0);
  EXPECT_EQ(inserted, rules["close_points"].get<int>() + rules["weak_tracking"].get<int>() +
                          rules["effective_spread"].get<int>() + rules["reference_fallback"].get<int>());
  EXPECT_GE(s["keyframes_created"].get<int>(), 2);

  // Loop detection: keyframe sequences, queried once per closed sequence (far fewer queries than
  // keyframes: bow-keyframe makes one per keyframe after the first 10, 32 on this cut).
  EXPECT_EQ(s["loop_detector"].get<std::string>(), "bow-sequence");
  const int queries = s["loop_queries"].get<int>();
  EXPECT_GE(queries, 1);
  EXPECT_LT(queries, s["keyframes_created"].get<int>() / 4);

  // ATE bound 6 mm. Measured with this configuration: 3.06 mm (deterministic, 2026-12-01; the heuristic
  // policy with bow-keyframe gives the identical trajectory, flow-only culling 3.0 mm, threaded 3.0 mm).
  // 6 mm is twice that, for floating-point differences between compilers and library versions that
  // change RANSAC and BA paths, and well below the 15 mm of the culling tests (test_pipeline_e2e.cpp).
  // What it guards: a default that breaks tracking (a keyframe rule starving the map, a wrong loop
  // correction). It does not measure culling: on this short, easy cut culling off scores 3.5 mm too.
  EXPECT_EQ(s["lost_frames"].get<int>(), 0);
  ASSERT_TRUE(r.ate_rmse.has_value());
  EXPECT_LT(*r.ate_rmse, 0.006);
  RecordProperty("ate_um", static_cast<int>(1e6 * *r.ate_rmse));
}

}  // namespace
}  // namespace sp::pipeline
