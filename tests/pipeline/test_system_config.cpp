// The system configuration: a key that is accepted is a key that is used, and the shipped
// config/stillpoint.yaml loads and documents every key.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "stillpoint/common/config_reader.hpp"
#include "stillpoint/common/error.hpp"
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

TEST(SystemConfig, ShippedFileLoadsWithItsDefaults) {
  const SystemConfig c = SystemConfig::load(kShipped);
  EXPECT_EQ(c.dynamic.mode, "auto");
  EXPECT_EQ(c.loop.detector, "bow-keyframe");  // scripts/bench_dev.sh and docs rely on this default
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
