// The system configuration: a key that is accepted is a key that is used, and the shipped
// config/stillpoint.yaml loads and documents every key.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <opencv2/imgproc.hpp>
#include <string>

#include "stillpoint/common/config_reader.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/io/frame.hpp"
#include "stillpoint/pipeline/dynamic_culling.hpp"
#include "stillpoint/pipeline/system_config.hpp"

namespace sp::pipeline {
namespace {

const std::filesystem::path kShipped = std::filesystem::path(SP_SOURCE_DIR) / "config" / "stillpoint.yaml";

SystemConfig load_text(const std::string& text) {
  const ConfigReader r = ConfigReader::from_string(text, "system.yaml");
  SystemConfig c = SystemConfig::from_yaml(r);
  r.finish();
  return c;
}

// dynamic.motion.mode used to be validated and then overwritten by dynamic.mode: now it is refused,
// naming the key, its line and the key to use instead.
TEST(SystemConfig, MotionCheckModeIsRefusedInFavourOfDynamicMode) {
  try {
    (void)load_text("dynamic:\n  mode: flow\n  motion:\n    lk_window: 15\n    mode: detector_only\n");
    FAIL() << "expected a ConfigError for dynamic.motion.mode";
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.key(), "dynamic.motion.mode");
    EXPECT_EQ(e.line(), 5);
    EXPECT_NE(std::string(e.what()).find("dynamic.mode"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("system.yaml:5"), std::string::npos) << e.what();
  }
}

TEST(SystemConfig, OtherMotionCheckKeysAndDynamicModeAreUsed) {
  const SystemConfig c =
      load_text("dynamic:\n  mode: flow\n  motion:\n    lk_window: 15\n    max_points: 400\n");
  EXPECT_EQ(c.dynamic.mode, "flow");
  EXPECT_EQ(c.dynamic.resolved_mode(), "flow");
  EXPECT_EQ(c.dynamic.motion.lk_window, 15);
  EXPECT_EQ(c.dynamic.motion.max_points, 400);
}

// The defaults are the paper's system (issue 14): YOLOX-nano (shipped in models/) + flow culling,
// adaptive keyframes, keyframe-sequence loop detection with the rising-edge rule.
TEST(SystemConfig, ShippedFileLoadsWithItsDefaults) {
  const SystemConfig c = SystemConfig::load(kShipped);
  EXPECT_EQ(c.dynamic.mode, "auto");
  EXPECT_EQ(c.dynamic.model, "models/yolox_nano/yolox_nano.onnx");
  EXPECT_EQ(c.dynamic.resolved_mode(), "detector+flow");
  EXPECT_TRUE(std::filesystem::exists(std::filesystem::path(SP_SOURCE_DIR) / c.dynamic.model));
  EXPECT_EQ(c.tracker.keyframes.policy, "adaptive");
  EXPECT_EQ(c.loop.detector, "bow-sequence");
  EXPECT_EQ(c.loop.detection.sequence.trigger, "rising-edge");
}

// dynamic.model resolves against the project root as loop_closing.vocabulary does; absolute paths
// are used as given; a missing file is an error naming it.
TEST(DynamicCulling, ModelPathResolvesAgainstTheProjectRoot) {
  DynamicConfig config;
  config.mode = "detector+flow";
  config.model = "models/yolox_nano/yolox_nano.onnx";
  const geo::CameraIntrinsics camera;  // TUM fr3 defaults
  const std::filesystem::path root(SP_SOURCE_DIR);
  {
    const DynamicCulling culling(config, camera, true, std::nullopt, root);
    EXPECT_EQ(culling.model_file(), root / "models/yolox_nano/yolox_nano.onnx");
  }
  config.model = (root / "models/yolox_nano/yolox_nano.onnx").string();
  {
    const DynamicCulling culling(config, camera, true, std::nullopt, "/nonexistent");
    EXPECT_EQ(culling.model_file(), root / "models/yolox_nano/yolox_nano.onnx");
  }
  config.model = "models/yolox_nano/yolox_nano.onnx";
  try {
    const DynamicCulling culling(config, camera, true, std::nullopt, "/nonexistent");
    FAIL() << "expected an error for a model missing under the project root";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/models/yolox_nano/yolox_nano.onnx"), std::string::npos)
        << e.what();
  }
  config.mode = "flow";  // no detector: the model is not touched
  const DynamicCulling flow(config, camera, true, std::nullopt, "/nonexistent");
  EXPECT_TRUE(flow.model_file().empty());
}

// dynamic.detector_min_score replaces the model's own score threshold (0 keeps the model's; the
// default is lower than the shipped models' 0.35) and is range-checked.
TEST(DynamicCulling, DetectorMinScoreReplacesTheModelsThreshold) {
  const geo::CameraIntrinsics camera;
  const std::filesystem::path root(SP_SOURCE_DIR);
  const std::string base = "dynamic:\n  mode: detector+flow\n  model: models/yolox_nano/yolox_nano.onnx\n";
  const float model_own =
      dyn::DetectorConfig::for_model((root / "models/yolox_nano/yolox_nano.onnx").string()).conf_threshold;
  const auto used_threshold = [&](const std::string& extra) {
    const DynamicCulling culling(load_text(base + extra).dynamic, camera, true, std::nullopt, root);
    return culling.detector_config().conf_threshold;
  };
  EXPECT_FLOAT_EQ(used_threshold(""), static_cast<float>(DynamicConfig{}.detector_min_score));
  EXPECT_LT(DynamicConfig{}.detector_min_score, model_own);
  EXPECT_FLOAT_EQ(used_threshold("  detector_min_score: 0\n"), model_own);
  EXPECT_FLOAT_EQ(used_threshold("  detector_min_score: 0.2\n"), 0.2f);
  EXPECT_THROW((void)load_text("dynamic:\n  detector_min_score: 1.5\n"), ConfigError);
}

// dynamic.detector_min_score_interior reaches the detector as its interior threshold (0 by default:
// one threshold for every box) and is range-checked.
TEST(DynamicCulling, InteriorMinScoreReachesTheDetector) {
  const geo::CameraIntrinsics camera;
  const std::filesystem::path root(SP_SOURCE_DIR);
  const std::string base = "dynamic:\n  mode: detector+flow\n  model: models/yolox_nano/yolox_nano.onnx\n";
  const auto used = [&](const std::string& extra) {
    const DynamicCulling culling(load_text(base + extra).dynamic, camera, true, std::nullopt, root);
    return culling.detector_config().interior_conf_threshold;
  };
  EXPECT_FLOAT_EQ(used(""), 0.f);
  EXPECT_FLOAT_EQ(used("  detector_min_score_interior: 0.35\n"), 0.35f);
  EXPECT_THROW((void)load_text("dynamic:\n  detector_min_score_interior: -0.1\n"), ConfigError);
}

// dynamic.oracle_moving_only: the oracle culls the ground-truth boxes of moving people only; false culls
// the standing ones too (dynsynth's still people are camera-facing billboards, docs/results.md
// "Session 40", so what their features are worth is measured with both).
TEST(DynamicCulling, OracleCullsStandingPeopleOnlyWhenAsked) {
  const std::filesystem::path dir = std::filesystem::path(SP_TEST_TMP_DIR) / "oracle_moving_only";
  std::filesystem::create_directories(dir);
  const auto boxes = dir / "boxes.txt";
  std::ofstream(boxes) << "1.000000 1 person 10 10 99 99 1\n1.000000 2 person 200 10 299 99 0\n";
  io::FrameData data;
  data.stamp = 1.0;
  data.bgr = cv::Mat(240, 320, CV_8UC3, cv::Scalar(128, 128, 128));
  data.depth = cv::Mat(240, 320, CV_32FC1, cv::Scalar(2.0f));
  cv::Mat gray;
  cv::cvtColor(data.bgr, gray, cv::COLOR_BGR2GRAY);
  // One keypoint in the walker's box, one in the standing person's, one on the background.
  const std::vector<cv::KeyPoint> keypoints{cv::KeyPoint(50.f, 50.f, 7.f), cv::KeyPoint(250.f, 50.f, 7.f),
                                            cv::KeyPoint(160.f, 200.f, 7.f)};
  const geo::CameraIntrinsics camera;
  const auto dropped = [&](bool moving_only) {
    DynamicConfig config;
    config.mode = "oracle";
    config.oracle_moving_only = moving_only;
    DynamicCulling culling(config, camera, true, boxes);
    culling.submit(data);
    return culling.process(data, gray, keypoints, std::nullopt).drop;
  };
  EXPECT_EQ(dropped(true), (std::vector<bool>{true, false, false}));
  EXPECT_EQ(dropped(false), (std::vector<bool>{true, true, false}));
  EXPECT_FALSE(load_text("dynamic:\n  oracle_moving_only: false\n").dynamic.oracle_moving_only);
}

// README: "every key documented". A line that sets a value (`key: value`) must carry a `#` comment
// (unit and range, see docs/CONVENTIONS.md); section headers (`key:` alone) need none.
TEST(SystemConfig, EveryKeyOfTheShippedFileHasAComment) {
  std::ifstream in(kShipped);
  ASSERT_TRUE(in) << kShipped;
  std::string line;
  int number = 0, keys = 0;
  while (std::getline(in, line)) {
    ++number;
    const auto first = line.find_first_not_of(' ');
    if (first == std::string::npos || line[first] == '#') continue;
    const auto colon = line.find(':', first);
    ASSERT_NE(colon, std::string::npos) << kShipped << ":" << number;
    const auto hash = line.find('#', colon);
    const std::string value =
        line.substr(colon + 1, hash == std::string::npos ? std::string::npos : hash - colon - 1);
    if (value.find_first_not_of(' ') == std::string::npos) continue;  // a section header
    ++keys;
    EXPECT_NE(hash, std::string::npos) << kShipped << ":" << number << " has no comment: " << line;
  }
  EXPECT_GT(keys, 40);
}

}  // namespace
}  // namespace sp::pipeline
