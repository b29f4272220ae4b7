// Camera settings written for other systems (--camera orbslam.yaml): ORB-SLAM2, ORB-SLAM3 (1.0 and the
// older layout) and stella_vslam (nested and dotted), as those projects ship them for TUM fr1, read into
// the same CameraConfig as our own config/camera/tum_fr1.yaml; KITTI trajectory output.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <sstream>

#include "stillpoint/common/error.hpp"
#include "stillpoint/io/camera_config.hpp"
#include "stillpoint/io/trajectory_io.hpp"
#include "test_util.hpp"

namespace sp::io {
namespace {

// TUM fr1's calibration (the values config/camera/tum_fr1.yaml carries), in each foreign layout.
const std::string kOrbSlam2 = R"(%YAML:1.0

# Camera Parameters. Adjust them!
Camera.fx: 517.306408
Camera.fy: 516.469215
Camera.cx: 318.643040
Camera.cy: 255.313989

Camera.k1: 0.262383
Camera.k2: -0.953104
Camera.p1: -0.005358
Camera.p2: 0.002628
Camera.k3: 1.163314

Camera.width: 640
Camera.height: 480
Camera.fps: 30.0
Camera.bf: 40.0
Camera.RGB: 1
ThDepth: 40.0
DepthMapFactor: 5000.0

ORBextractor.nFeatures: 1000
Viewer.KeyFrameSize: 0.05
)";

const std::string kOrbSlam3 = R"(%YAML:1.0
File.version: "1.0"
Camera.type: "PinHole"
Camera1.fx: 517.306408
Camera1.fy: 516.469215
Camera1.cx: 318.643040
Camera1.cy: 255.313989
Camera1.k1: 0.262383
Camera1.k2: -0.953104
Camera1.p1: -0.005358
Camera1.p2: 0.002628
Camera1.k3: 1.163314
Camera.width: 640
Camera.height: 480
Camera.fps: 30
Camera.RGB: 1
Stereo.ThDepth: 40.0
Stereo.b: 0.07732
RGBD.DepthMapFactor: 5000.0
IMU.T_b_c1: !!opencv-matrix
   rows: 4
   cols: 4
   dt: f
   data: [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]
)";

const std::string kStella = R"(# TUM RGBD model for fr1
Camera:
  name: "TUM RGBD 1"
  setup: "RGBD"
  model: "perspective"
  fx: 517.306408
  fy: 516.469215
  cx: 318.643040
  cy: 255.313989
  k1: 0.262383
  k2: -0.953104
  p1: -0.005358
  p2: 0.002628
  k3: 1.163314
  fps: 30.0
  cols: 640
  rows: 480
  focal_x_baseline: 40.0
  color_order: "RGB"
Preprocessing:
  min_size: 800
  depthmap_factor: 5000.0
Feature:
  name: "default ORB feature extraction setting"
)";

const std::string kStellaDotted = R"(Camera.name: "TUM RGBD 1"
Camera.setup: "RGBD"
Camera.model: "perspective"
Camera.fx: 517.306408
Camera.fy: 516.469215
Camera.cx: 318.643040
Camera.cy: 255.313989
Camera.k1: 0.262383
Camera.k2: -0.953104
Camera.p1: -0.005358
Camera.p2: 0.002628
Camera.k3: 1.163314
Camera.fps: 30.0
Camera.cols: 640
Camera.rows: 480
Camera.color_order: "RGB"
depthmap_factor: 5000.0
)";

void expect_tum_fr1(const CameraConfig& c) {
  EXPECT_EQ(c.intrinsics.width, 640);
  EXPECT_EQ(c.intrinsics.height, 480);
  EXPECT_DOUBLE_EQ(c.intrinsics.fx, 517.306408);
  EXPECT_DOUBLE_EQ(c.intrinsics.fy, 516.469215);
  EXPECT_DOUBLE_EQ(c.intrinsics.cx, 318.643040);
  EXPECT_DOUBLE_EQ(c.intrinsics.cy, 255.313989);
  EXPECT_DOUBLE_EQ(c.intrinsics.k1, 0.262383);
  EXPECT_DOUBLE_EQ(c.intrinsics.k2, -0.953104);
  EXPECT_DOUBLE_EQ(c.intrinsics.p1, -0.005358);
  EXPECT_DOUBLE_EQ(c.intrinsics.p2, 0.002628);
  EXPECT_DOUBLE_EQ(c.intrinsics.k3, 1.163314);
  EXPECT_DOUBLE_EQ(c.depth_factor, 5000.0);
  EXPECT_DOUBLE_EQ(c.fps, 30.0);
}

TEST(CameraFormats, OrbSlam2) {
  const auto f = test::write_text(test::scratch_dir() / "TUM1.yaml", kOrbSlam2);
  EXPECT_EQ(detect_camera_format(f), CameraFormat::OrbSlam);
  expect_tum_fr1(load_camera_config(f));
}

TEST(CameraFormats, OrbSlam3) {
  const auto f = test::write_text(test::scratch_dir() / "TUM1.yaml", kOrbSlam3);
  EXPECT_EQ(detect_camera_format(f), CameraFormat::OrbSlam);
  expect_tum_fr1(load_camera_config(f));
}

TEST(CameraFormats, StellaNestedAndDotted) {
  const auto dir = test::scratch_dir();
  const auto nested = test::write_text(dir / "stella.yaml", kStella);
  const auto dotted = test::write_text(dir / "openvslam.yaml", kStellaDotted);
  EXPECT_EQ(detect_camera_format(nested), CameraFormat::Stella);
  EXPECT_EQ(detect_camera_format(dotted), CameraFormat::Stella);
  expect_tum_fr1(load_camera_config(nested));
  expect_tum_fr1(load_camera_config(dotted));
}

// The shipped TUM preset and the foreign files describe the same camera.
TEST(CameraFormats, ShippedTumFr1PresetAgrees) {
  const auto ours =
      load_camera_config(std::filesystem::path(SP_SOURCE_DIR) / "config" / "camera" / "tum_fr1.yaml");
  EXPECT_EQ(detect_camera_format(std::filesystem::path(SP_SOURCE_DIR) / "config" / "camera" / "tum_fr1.yaml"),
            CameraFormat::StillPoint);
  const auto orb = load_camera_config(test::write_text(test::scratch_dir() / "TUM1.yaml", kOrbSlam2));
  EXPECT_NEAR(ours.intrinsics.fx, orb.intrinsics.fx, 1e-3);
  EXPECT_NEAR(ours.intrinsics.cy, orb.intrinsics.cy, 1e-3);
  EXPECT_NEAR(ours.intrinsics.k3, orb.intrinsics.k3, 1e-3);
  EXPECT_DOUBLE_EQ(ours.depth_factor, orb.depth_factor);
}

// Unsupported models and missing keys are ConfigErrors naming the key and its line.
TEST(CameraFormats, ErrorsNameKeyAndLine) {
  const auto dir = test::scratch_dir();
  std::string fisheye = kOrbSlam3;
  fisheye.replace(fisheye.find("\"PinHole\""), 9, "\"KannalaBrandt8\"");
  try {
    (void)load_camera_config(test::write_text(dir / "kb.yaml", fisheye));
    FAIL() << "expected a ConfigError for a fisheye camera";
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.key(), "Camera.type");
    EXPECT_EQ(e.line(), 3);  // the %YAML line is kept, so lines are the file's
    EXPECT_NE(std::string(e.what()).find("KannalaBrandt8"), std::string::npos) << e.what();
  }
  std::string no_factor = kOrbSlam2;
  no_factor.erase(no_factor.find("DepthMapFactor"), std::string("DepthMapFactor: 5000.0").size());
  try {
    (void)load_camera_config(test::write_text(dir / "nofactor.yaml", no_factor));
    FAIL() << "expected a ConfigError for a missing depth factor";
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.key(), "DepthMapFactor");
  }
  std::string mono = kStella;
  mono.replace(mono.find("\"RGBD\""), 6, "\"monocular\"");
  try {
    (void)load_camera_config(test::write_text(dir / "mono.yaml", mono));
    FAIL() << "expected a ConfigError for a monocular stella setup";
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.key(), "Camera.setup");
    EXPECT_EQ(e.line(), 4);
  }
  std::string bad_cx = kStella;
  bad_cx.replace(bad_cx.find("318.643040"), 10, "918.643040");  // outside the 640-pixel image
  EXPECT_THROW((void)load_camera_config(test::write_text(dir / "cx.yaml", bad_cx)), ConfigError);
}

// KITTI: 12 numbers per pose, the rows of [R | t]; write_stamps gives the matching times.
TEST(TrajectoryIo, KittiFormat) {
  const auto dir = test::scratch_dir();
  StampedPose a;
  a.stamp = 1.5;
  a.t = {1, 2, 3};
  StampedPose b;
  b.stamp = 2.25;
  b.t = {-1, 0.5, 0};
  b.q = Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()));
  write_kitti_trajectory(dir / "kitti.txt", {a, b});
  write_stamps(dir / "times.txt", {a, b});
  std::ifstream in(dir / "kitti.txt");
  std::string line;
  std::vector<std::vector<double>> rows;
  while (std::getline(in, line)) {
    std::istringstream s(line);
    std::vector<double> v;
    double x = 0;
    while (s >> x) v.push_back(x);
    rows.push_back(v);
  }
  ASSERT_EQ(rows.size(), 2u);
  ASSERT_EQ(rows[0].size(), 12u);
  const std::vector<double> identity_at_123 = {1, 0, 0, 1, 0, 1, 0, 2, 0, 0, 1, 3};
  for (int i = 0; i < 12; ++i) EXPECT_NEAR(rows[0][i], identity_at_123[i], 1e-12) << i;
  // 90° about z: R = [[0 -1 0] [1 0 0] [0 0 1]].
  const std::vector<double> turned = {0, -1, 0, -1, 1, 0, 0, 0.5, 0, 0, 1, 0};
  for (int i = 0; i < 12; ++i) EXPECT_NEAR(rows[1][i], turned[i], 1e-9) << i;
  std::ifstream times(dir / "times.txt");
  double t0 = 0, t1 = 0;
  times >> t0 >> t1;
  EXPECT_DOUBLE_EQ(t0, 1.5);
  EXPECT_DOUBLE_EQ(t1, 2.25);
}

}  // namespace
}  // namespace sp::io
