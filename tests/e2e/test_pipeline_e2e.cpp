// End-to-end: the whole system on ~150 frames of the shared dynsynth sequences, in deterministic
// mode, checked against ground truth (ATE bounds), for reproducibility and for clean early stops.
#include <gtest/gtest.h>

#include <atomic>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "../support/shared_data.hpp"
#include "stillpoint/api/runner.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/io/tum_sequence.hpp"

namespace sp::pipeline {
namespace {

using api::run_slam;  // stillpoint run's runner, on the public API
using api::RunOptions;
using api::RunResult;

const std::filesystem::path kData = std::filesystem::path(SP_SHARED_DIR) / "data" / "dynsynth";
const std::filesystem::path kConfig = std::filesystem::path(SP_SOURCE_DIR) / "config" / "stillpoint.yaml";

std::filesystem::path scratch(const std::string& name) {
  const auto dir = std::filesystem::path(SP_TEST_TMP_DIR) / "e2e" / name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

std::string read_file(const std::filesystem::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

RunResult run(const std::string& sequence, const std::string& out_name, const std::string& dynamic_mode,
              bool deterministic = true, const std::atomic<bool>* stop = nullptr,
              const std::filesystem::path& detector_model = {}, int detector_latency = 0,
              int mapping_latency = 0) {
  const auto dir = kData / sequence;
  io::TumSequence source(dir);
  SystemConfig config = SystemConfig::load(kConfig);
  config.dynamic.mode = dynamic_mode;
  if (!detector_model.empty()) config.dynamic.model = detector_model.string();
  config.dynamic.deterministic_detector_latency = detector_latency;
  config.pipeline.deterministic_mapping_latency = mapping_latency;
  RunOptions options;
  options.out_dir = scratch(out_name);
  options.deterministic = deterministic;
  options.progress = false;
  options.groundtruth = source.groundtruth_path();
  options.boxes_file = dir / "boxes.txt";
  options.masks_dir = dir / "masks";
  options.stop = stop;
  options.project_root = SP_SOURCE_DIR;
  return run_slam(source, config, options);
}

class EndToEnd : public ::testing::Test {
 protected:
  void SetUp() override {
    SP_REQUIRE_SHARED(kData / "office_a_static_xyz_150", kData / "office_a_walking_xyz_150");
  }
};

TEST_F(EndToEnd, StaticSequenceTracksEveryFrameWithinOneCentimetre) {
  const RunResult r = run("office_a_static_xyz_150", "static", "off");
  ASSERT_TRUE(r.completed);
  EXPECT_EQ(r.stats["lost_frames"].get<int>(), 0);
  EXPECT_EQ(r.stats["tracked_frames"].get<int>(), 150);
  ASSERT_TRUE(r.ate_rmse.has_value());
  EXPECT_LT(*r.ate_rmse, 0.01);
}

TEST_F(EndToEnd, WalkingSequenceWithOracleCullingStaysAccurate) {
  const RunResult r = run("office_a_walking_xyz_150", "walking_oracle", "oracle");
  ASSERT_TRUE(r.completed);
  ASSERT_TRUE(r.ate_rmse.has_value());
  EXPECT_LT(*r.ate_rmse, 0.015);
  // Oracle culling removes the features of the people flagged moving; the masks also cover people
  // standing still, which stay (they are static), so recall against the masks is well below 1.
  EXPECT_GT(r.stats["culling_score"]["recall"].get<double>(), 0.5);
  EXPECT_GT(r.stats["culling_score"]["culled_keypoints"].get<int>(), 1000);
}

// The method as users run it: a real detector (YOLOX-nano, every 3rd frame, boxes carried by flow)
// plus the motion check, static-until-proven people and the pose guard. Bound: the oracle test's.
TEST_F(EndToEnd, WalkingSequenceWithDetectorAndFlowStaysAccurate) {
  const auto model = std::filesystem::path(SP_SHARED_DIR) / "models" / "yolox_nano.onnx";
  SP_REQUIRE_SHARED(model);
  const RunResult r =
      run("office_a_walking_xyz_150", "walking_detector_flow", "detector+flow", true, nullptr, model);
  ASSERT_TRUE(r.completed);
  EXPECT_EQ(r.stats["dynamic_mode"].get<std::string>(), "detector+flow");
  EXPECT_EQ(r.stats["lost_frames"].get<int>(), 0);
  ASSERT_TRUE(r.ate_rmse.has_value());
  EXPECT_LT(*r.ate_rmse, 0.015);
  EXPECT_GT(r.stats["stages_ms"]["detector"]["count"].get<int>(), 0);  // the detector really ran
  EXPECT_GT(r.stats["culling_score"]["recall"].get<double>(), 0.5);
}

// As above with every detection seen 5 frames after its frame (older than dynamic.max_detection_age,
// as on a busy CPU): the boxes carried by flow must still cover the people. Same bounds.
TEST_F(EndToEnd, WalkingSequenceWithLateDetectionsStaysAccurate) {
  const auto model = std::filesystem::path(SP_SHARED_DIR) / "models" / "yolox_nano.onnx";
  SP_REQUIRE_SHARED(model);
  const RunResult r =
      run("office_a_walking_xyz_150", "walking_late_boxes", "detector+flow", true, nullptr, model, 5);
  ASSERT_TRUE(r.completed);
  EXPECT_EQ(r.stats["lost_frames"].get<int>(), 0);
  ASSERT_TRUE(r.ate_rmse.has_value());
  EXPECT_LT(*r.ate_rmse, 0.015);
  EXPECT_GT(r.stats["culling_score"]["recall"].get<double>(), 0.5);
  // The latency took effect: the trajectory differs from the on-time run's (same seeds otherwise).
  const RunResult on_time =
      run("office_a_walking_xyz_150", "walking_on_time_boxes", "detector+flow", true, nullptr, model, 0);
  ASSERT_TRUE(on_time.completed);
  const auto e2e = std::filesystem::path(SP_TEST_TMP_DIR) / "e2e";
  EXPECT_NE(read_file(e2e / "walking_late_boxes" / "trajectory.txt"),
            read_file(e2e / "walking_on_time_boxes" / "trajectory.txt"));
}

// Keyframes reaching local mapping 4 frames late, with tracking told mapping is busy meanwhile (a
// lagging mapper on a loaded CPU): tracking must not depend on the mapper keeping up. Same bounds.
TEST_F(EndToEnd, WalkingSequenceWithLaggingMappingStaysAccurate) {
  const RunResult r = run("office_a_walking_xyz_150", "walking_mapping_lag", "flow", true, nullptr, {}, 0, 4);
  ASSERT_TRUE(r.completed);
  EXPECT_EQ(r.stats["lost_frames"].get<int>(), 0);
  ASSERT_TRUE(r.ate_rmse.has_value());
  EXPECT_LT(*r.ate_rmse, 0.015);
  const RunResult on_time = run("office_a_walking_xyz_150", "walking_mapping_on_time", "flow");
  ASSERT_TRUE(on_time.completed);
  const auto e2e = std::filesystem::path(SP_TEST_TMP_DIR) / "e2e";
  EXPECT_NE(read_file(e2e / "walking_mapping_lag" / "trajectory.txt"),
            read_file(e2e / "walking_mapping_on_time" / "trajectory.txt"));
}

TEST_F(EndToEnd, DeterministicModeGivesIdenticalTrajectories) {
  const RunResult a = run("office_a_walking_xyz_150", "det_a", "flow");
  const RunResult b = run("office_a_walking_xyz_150", "det_b", "flow");
  const std::string ta =
      read_file(std::filesystem::path(SP_TEST_TMP_DIR) / "e2e" / "det_a" / "trajectory.txt");
  const std::string tb =
      read_file(std::filesystem::path(SP_TEST_TMP_DIR) / "e2e" / "det_b" / "trajectory.txt");
  ASSERT_FALSE(ta.empty());
  EXPECT_EQ(ta, tb);
}

TEST_F(EndToEnd, StopMidRunWritesTheTrajectorySoFarAndShutsDownCleanly) {
  // A frame source that raises the stop flag after 40 frames, as SIGINT does, with threads running.
  std::atomic<bool> stop{false};
  const auto dir = kData / "office_a_static_xyz_150";
  struct StoppingSource final : io::FrameSource {
    StoppingSource(const std::filesystem::path& d, std::atomic<bool>& flag) : inner(d), stop(flag) {}
    std::optional<io::FrameData> next() override {
      if (++count == 40) stop = true;
      return inner.next();
    }
    [[nodiscard]] std::size_t size_hint() const override { return inner.size_hint(); }
    [[nodiscard]] const io::CameraConfig& camera() const override { return inner.camera(); }
    [[nodiscard]] std::size_t skipped_frames() const override { return inner.skipped_frames(); }
    io::TumSequence inner;
    std::atomic<bool>& stop;
    int count = 0;
  } source(dir, stop);
  SystemConfig config = SystemConfig::load(kConfig);
  config.dynamic.mode = "off";
  RunOptions options;
  options.out_dir = scratch("stopped");
  options.progress = false;
  options.stop = &stop;
  options.project_root = SP_SOURCE_DIR;
  const RunResult r = run_slam(source, config, options);
  EXPECT_FALSE(r.completed);
  const auto trajectory = read_file(options.out_dir / "trajectory.txt");
  const auto lines = std::count(trajectory.begin(), trajectory.end(), '\n');
  EXPECT_GE(lines, 39);
  EXPECT_LE(lines, 41);
  EXPECT_TRUE(std::filesystem::exists(options.out_dir / "stats.json"));
  EXPECT_EQ(r.stats.value("stop_reason", ""), "stop requested");
}

// An error mid-run (here from the frame source) ends the run like a stop request: what was tracked is
// written, and stats.json says why the run ended.
TEST_F(EndToEnd, ErrorMidRunIsWrittenAsTheStopReason) {
  struct FailingSource final : io::FrameSource {
    explicit FailingSource(const std::filesystem::path& d) : inner(d) {}
    std::optional<io::FrameData> next() override {
      if (++count == 21) throw sp::Error("camera unplugged");
      return inner.next();
    }
    [[nodiscard]] std::size_t size_hint() const override { return inner.size_hint(); }
    [[nodiscard]] const io::CameraConfig& camera() const override { return inner.camera(); }
    [[nodiscard]] std::size_t skipped_frames() const override { return inner.skipped_frames(); }
    io::TumSequence inner;
    int count = 0;
  } source(kData / "office_a_static_xyz_150");
  SystemConfig config = SystemConfig::load(kConfig);
  config.dynamic.mode = "off";
  RunOptions options;
  options.out_dir = scratch("failed_source");
  options.progress = false;
  options.deterministic = true;
  options.project_root = SP_SOURCE_DIR;
  const RunResult r = run_slam(source, config, options);
  EXPECT_FALSE(r.completed);
  EXPECT_EQ(r.stop_reason, "stopped at frame 20: camera unplugged");
  EXPECT_EQ(r.stats.value("stop_reason", ""), r.stop_reason);
  EXPECT_FALSE(r.stats.value("completed", true));
  const auto trajectory = read_file(options.out_dir / "trajectory.txt");
  EXPECT_EQ(std::count(trajectory.begin(), trajectory.end(), '\n'), 21);  // header + 20 frames
}

TEST_F(EndToEnd, ThreadedRunFinishesAndTracksEveryFrame) {
  const RunResult r = run("office_a_static_xyz_150", "threaded", "off", /*deterministic=*/false);
  ASSERT_TRUE(r.completed);
  EXPECT_FALSE(r.stats.contains("stop_reason"));
  EXPECT_EQ(r.stats["tracked_frames"].get<int>(), 150);
  ASSERT_TRUE(r.ate_rmse.has_value());
  EXPECT_LT(*r.ate_rmse, 0.02);
  // The map lock time of the tracking thread, per frame: part of each frame's tracking time, so its
  // median, p95 and max are no larger than the tracking time's.
  const auto& stages = r.stats["stages_ms"];
  ASSERT_TRUE(stages.contains("track_lock"));
  const auto& lock = stages["track_lock"];
  const auto& track = stages["track"];
  EXPECT_EQ(lock["count"].get<int>(), 150);
  EXPECT_GT(lock["median_ms"].get<double>(), 0.0);
  for (const char* k : {"median_ms", "p95_ms", "max_ms"})
    EXPECT_LE(lock[k].get<double>(), track[k].get<double>()) << k;
}

}  // namespace
}  // namespace sp::pipeline
