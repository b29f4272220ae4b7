// `stillpoint run --set section.key=value`: overrides go through the same validation as the file.
#include <gtest/gtest.h>

#include "stillpoint/common/error.hpp"
#include "stillpoint/pipeline/system_config.hpp"

namespace sp::pipeline {
namespace {

const std::filesystem::path kConfig = std::filesystem::path(SP_SOURCE_DIR) / "config" / "stillpoint.yaml";

TEST(ConfigOverrides, ValuesReachTheTypedConfig) {
  const SystemConfig base = SystemConfig::load(kConfig);
  const SystemConfig c = SystemConfig::load(
      kConfig, {"dynamic.motion.static_proof_frames=3", "tracking.pose_guard.enabled=false",
                "dynamic.detector_interval=1", "dynamic.motion.always_dynamic_classes=[person, dog]"});
  EXPECT_EQ(c.dynamic.motion.static_proof_frames, 3);
  EXPECT_FALSE(c.tracker.guard.enabled);
  EXPECT_EQ(c.dynamic.detector_interval, 1);
  EXPECT_EQ(c.dynamic.motion.always_dynamic_classes, (std::vector<std::string>{"person", "dog"}));
  // Untouched keys keep the file's values.
  EXPECT_EQ(c.orb.n_features, base.orb.n_features);
  EXPECT_EQ(c.loop.detector, base.loop.detector);
}

TEST(ConfigOverrides, BadOverridesAreConfigErrors) {
  EXPECT_THROW(SystemConfig::load(kConfig, {"dynamic.motion.no_such_key=1"}), ConfigError);  // unknown key
  EXPECT_THROW(SystemConfig::load(kConfig, {"dynamic.detector_interval=0"}), ConfigError);   // out of range
  EXPECT_THROW(SystemConfig::load(kConfig, {"dynamic.detector_interval"}), ConfigError);     // no '='
  EXPECT_THROW(SystemConfig::load(kConfig, {"dynamic..x=1"}), ConfigError);                  // empty key
  EXPECT_THROW(SystemConfig::load(kConfig, {"tracking.pose_guard.enabled=maybe"}), ConfigError);  // type
}

}  // namespace
}  // namespace sp::pipeline
