#include <gtest/gtest.h>

#include "../support/shared_data.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/io/camera_config.hpp"
#include "test_util.hpp"

namespace sp::io {
namespace {

const std::string kValid =
    "width: 640\nheight: 480\nfx: 535.4\nfy: 539.2\ncx: 320.1\ncy: 247.6\n"
    "k1: 0.1\nk2: -0.2\np1: 0.001\np2: -0.002\nk3: 0.3\ndepth_factor: 1000.0\nfps: 15.0\n";

// Loads `text` as a camera.yaml and returns the ConfigError (fails the test when none is thrown).
ConfigError load_error(const std::string& text) {
  const auto f = test::write_text(test::scratch_dir() / "camera.yaml", text);
  try {
    (void)load_camera_config(f);
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.file(), f.string());
    return e;
  }
  ADD_FAILURE() << "no ConfigError for:\n" << text;
  return ConfigError("", 0, "", "");
}

TEST(CameraConfig, ReadsAllKeys) {
  const auto c =
      load_camera_config(test::write_text(test::scratch_dir() / "camera.yaml", kValid + "depth_max: 4.5\n"));
  EXPECT_EQ(c.intrinsics.width, 640);
  EXPECT_EQ(c.intrinsics.height, 480);
  EXPECT_DOUBLE_EQ(c.intrinsics.fx, 535.4);
  EXPECT_DOUBLE_EQ(c.intrinsics.cy, 247.6);
  EXPECT_DOUBLE_EQ(c.intrinsics.k1, 0.1);
  EXPECT_DOUBLE_EQ(c.intrinsics.p2, -0.002);
  EXPECT_DOUBLE_EQ(c.intrinsics.k3, 0.3);
  EXPECT_DOUBLE_EQ(c.depth_factor, 1000.0);
  EXPECT_DOUBLE_EQ(c.fps, 15.0);
  EXPECT_DOUBLE_EQ(c.depth_min, 0.1);  // default
  EXPECT_DOUBLE_EQ(c.depth_max, 4.5);
}

TEST(CameraConfig, MissingKeyIsNamed) {
  std::string text = kValid;
  text.erase(text.find("fy: 539.2\n"), 10);
  EXPECT_EQ(load_error(text).key(), "fy");
}

TEST(CameraConfig, UnknownKeyIsNamedWithItsLine) {
  const auto e = load_error(kValid + "fz: 3.0\n");
  EXPECT_EQ(e.key(), "fz");
  EXPECT_EQ(e.line(), 14);
}

TEST(CameraConfig, OutOfRangeValuesAreNamedWithTheirLine) {
  std::string text = kValid;
  text.replace(text.find("fx: 535.4"), 9, "fx: -5.0");
  const auto e = load_error(text);
  EXPECT_EQ(e.key(), "fx");
  EXPECT_EQ(e.line(), 3);
  EXPECT_NE(std::string(e.what()).find("out of range"), std::string::npos) << e.what();

  std::string cx = kValid;
  cx.replace(cx.find("cx: 320.1"), 9, "cx: 900.0");  // outside the 640 px image
  EXPECT_EQ(load_error(cx).key(), "cx");
  EXPECT_EQ(load_error(kValid + "depth_min: 5.0\ndepth_max: 2.0\n").key(), "depth_max");
  std::string df = kValid;
  df.replace(df.find("depth_factor: 1000.0"), 20, "depth_factor: 0.0");
  EXPECT_EQ(load_error(df).key(), "depth_factor");
}

TEST(CameraConfig, NonNumericValueIsAConfigError) {
  std::string text = kValid;
  text.replace(text.find("width: 640"), 10, "width: wide");
  EXPECT_EQ(load_error(text).key(), "width");
}

TEST(CameraConfig, ShippedPresetsAndSharedSequenceLoad) {
  SP_REQUIRE_SHARED(SP_SHARED_DIR "/data/dynsynth/office_a_static_xyz_150/camera.yaml");
  const std::filesystem::path presets = SP_SOURCE_DIR "/config/camera";
  const auto fr1 = load_camera_config(presets / "tum_fr1.yaml");
  EXPECT_NEAR(fr1.intrinsics.fx, 517.3, 0.01);
  EXPECT_NEAR(fr1.intrinsics.k3, 1.1633, 1e-4);
  EXPECT_TRUE(fr1.intrinsics.has_distortion());
  const auto fr2 = load_camera_config(presets / "tum_fr2.yaml");
  EXPECT_NEAR(fr2.intrinsics.cx, 325.1, 0.05);
  const auto fr3 = load_camera_config(presets / "tum_fr3.yaml");
  EXPECT_FALSE(fr3.intrinsics.has_distortion());
  EXPECT_DOUBLE_EQ(fr3.depth_factor, 5000.0);
  const auto dyn = load_camera_config(presets / "dynsynth.yaml");
  const auto shared = load_camera_config(SP_SHARED_DIR "/data/dynsynth/office_a_static_xyz_150/camera.yaml");
  EXPECT_DOUBLE_EQ(dyn.intrinsics.fx, shared.intrinsics.fx);
  EXPECT_DOUBLE_EQ(dyn.intrinsics.cy, shared.intrinsics.cy);
  EXPECT_DOUBLE_EQ(dyn.depth_factor, shared.depth_factor);
}

}  // namespace
}  // namespace sp::io
