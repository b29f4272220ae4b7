// The run's PLY writer against the report's PLY reader, and the run artifacts (thumbnails, index,
// dense cloud without the dynamic regions).
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "stillpoint/common/error.hpp"
#include "stillpoint/map/map.hpp"
#include "stillpoint/pipeline/run_artifacts.hpp"
#include "stillpoint/report/ply_reader.hpp"
#include "synthetic_run.hpp"

namespace sp {
namespace {

std::filesystem::path scratch(const std::string& name) {
  const auto dir = std::filesystem::path(SP_TEST_TMP_DIR) / "report" / name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

TEST(Ply, RoundTripKeepsHeaderCountAndValues) {
  const auto file = scratch("ply_roundtrip") / "cloud.ply";
  std::vector<pipeline::PlyPoint> points = {
      {1.5f, -2.25f, 3.125f, 255, 0, 7}, {-1e6f, 1e-6f, 0.f, 1, 2, 3}, {0.1f, 0.2f, 0.3f, 128, 64, 32}};
  pipeline::write_ply(file, points, "unit test");
  // Header as the format says, then exactly 15 bytes per vertex.
  const std::string bytes = test::read_file(file);
  const std::string header =
      "ply\nformat binary_little_endian 1.0\ncomment unit test\nelement vertex 3\nproperty float x\nproperty "
      "float "
      "y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n";
  ASSERT_EQ(bytes.substr(0, header.size()), header);
  EXPECT_EQ(bytes.size(), header.size() + 3 * 15);
  // Little endian on disk: 1.5f = 0x3FC00000.
  EXPECT_EQ(static_cast<unsigned char>(bytes[header.size() + 2]), 0xC0);
  EXPECT_EQ(static_cast<unsigned char>(bytes[header.size() + 3]), 0x3F);

  const report::PointCloud cloud = report::read_ply(file);
  ASSERT_EQ(cloud.size(), points.size());
  ASSERT_EQ(cloud.rgb.size(), points.size() * 3);
  for (std::size_t i = 0; i < points.size(); ++i) {
    EXPECT_EQ(cloud.xyz[3 * i], points[i].x);
    EXPECT_EQ(cloud.xyz[3 * i + 1], points[i].y);
    EXPECT_EQ(cloud.xyz[3 * i + 2], points[i].z);
    EXPECT_EQ(cloud.rgb[3 * i], points[i].r);
    EXPECT_EQ(cloud.rgb[3 * i + 1], points[i].g);
    EXPECT_EQ(cloud.rgb[3 * i + 2], points[i].b);
  }
}

TEST(Ply, EmptyCloudRoundTrips) {
  const auto file = scratch("ply_empty") / "empty.ply";
  pipeline::write_ply(file, {});
  EXPECT_EQ(report::read_ply(file).size(), 0u);
}

TEST(Ply, ReaderAcceptsAsciiWithExtraProperties) {
  const auto file = scratch("ply_ascii") / "a.ply";
  test::write_file(file,
                   "ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\nproperty double y\nproperty "
                   "double z\nproperty float nx\nend_header\n1 2 3 0.5\n-4 5.5 6 0.1\n");
  const auto cloud = report::read_ply(file);
  ASSERT_EQ(cloud.size(), 2u);
  EXPECT_TRUE(cloud.rgb.empty());
  EXPECT_FLOAT_EQ(cloud.xyz[3], -4.f);
  EXPECT_FLOAT_EQ(cloud.xyz[4], 5.5f);
}

TEST(Ply, TruncatedOrForeignFilesAreRejectedWithTheFileName) {
  const auto dir = scratch("ply_bad");
  pipeline::write_ply(dir / "t.ply", {{1, 2, 3, 4, 5, 6}, {7, 8, 9, 10, 11, 12}});
  std::string bytes = test::read_file(dir / "t.ply");
  bytes.resize(bytes.size() - 4);
  test::write_file(dir / "t.ply", bytes);
  try {
    (void)report::read_ply(dir / "t.ply");
    FAIL() << "truncated PLY accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("t.ply"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("truncated"), std::string::npos) << e.what();
  }
  test::write_file(dir / "b.ply", "ply\nformat binary_big_endian 1.0\nelement vertex 0\nend_header\n");
  EXPECT_THROW((void)report::read_ply(dir / "b.ply"), InputError);
  test::write_file(dir / "c.txt", "hello\n");
  EXPECT_THROW((void)report::read_ply(dir / "c.txt"), InputError);
  EXPECT_THROW((void)report::read_ply(dir / "missing.ply"), InputError);
}

io::FrameData synthetic_frame(std::size_t index, float depth_m) {
  io::FrameData f;
  f.index = index;
  f.stamp = 10.0 + 0.1 * static_cast<double>(index);
  f.bgr = cv::Mat(120, 160, CV_8UC3, cv::Scalar(20, 120, 220));
  f.depth = cv::Mat(120, 160, CV_32F, cv::Scalar(depth_m));
  return f;
}

geo::CameraIntrinsics small_camera() {
  geo::CameraIntrinsics cam;
  cam.width = 160;
  cam.height = 120;
  cam.fx = cam.fy = 100;
  cam.cx = 80;
  cam.cy = 60;
  return cam;
}

TEST(RunArtifacts, ThumbnailsStayFewAndEvenlySpread) {
  const auto out = scratch("thumbs");
  pipeline::ArtifactOptions options;
  options.out_dir = out;
  options.max_thumbnails = 8;
  options.expected_frames = 0;  // unknown length: the stride has to grow while running
  pipeline::RunArtifacts artifacts(options, small_camera());
  const std::vector<cv::KeyPoint> keypoints = {cv::KeyPoint(20, 20, 7), cv::KeyPoint(80, 60, 7),
                                               cv::KeyPoint(100, 90, 7)};
  const std::vector<bool> dynamic = {false, true, false};
  for (std::size_t i = 0; i < 100; ++i)
    artifacts.on_frame(synthetic_frame(i, 2.f), keypoints, dynamic, {}, {});
  map::Map map;
  map::MapView view = map.view();
  const nlohmann::json stats = artifacts.write(view);
  EXPECT_EQ(stats.at("map_points_ply"), 0);

  std::vector<std::filesystem::path> jpegs;
  for (const auto& e : std::filesystem::directory_iterator(out / "culled"))
    if (e.path().extension() == ".jpg") jpegs.push_back(e.path());
  EXPECT_GE(jpegs.size(), 4u);
  EXPECT_LE(jpegs.size(), 8u);
  const auto index = nlohmann::json::parse(test::read_file(out / "culled" / "index.json"));
  ASSERT_EQ(index.at("frames").size(), jpegs.size());
  const std::size_t stride = index.at("stride");
  for (const auto& f : index.at("frames")) {
    EXPECT_EQ(f.at("index").get<std::size_t>() % stride, 0u);
    EXPECT_EQ(f.at("culled"), 1);
    EXPECT_EQ(f.at("features"), 3);
    const cv::Mat img = cv::imread((out / "culled" / f.at("file").get<std::string>()).string());
    ASSERT_FALSE(img.empty());
    EXPECT_EQ(img.cols, 320);
    // The culled feature at (80, 60) is drawn red at twice the scale.
    const cv::Vec3b c = img.at<cv::Vec3b>(120, 160);
    EXPECT_GT(c[2], 150);
    EXPECT_LT(c[1], 120);
  }
  EXPECT_GE(index.at("frames").back().at("index").get<std::size_t>() + stride, 100u)
      << "the picked frames should reach the end of the run";
  EXPECT_TRUE(std::filesystem::exists(out / "map_points.ply"));
}

TEST(RunArtifacts, DenseCloudLeavesOutDynamicRegions) {
  const auto out = scratch("dense");
  pipeline::ArtifactOptions options;
  options.out_dir = out;
  options.dense_cloud = true;
  options.dense_step = 4;
  options.dense_voxel = 0;  // keep every sampled pixel so counts are exact
  options.dynamic_margin_px = 12;
  pipeline::RunArtifacts artifacts(options, small_camera());
  map::Map map;
  map::KeyframeId id = map::kNoKeyframe;
  {
    map::MapView view = map.view();
    map::Keyframe kf;
    kf.T_cw = geo::SE3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, 0, -1));  // camera at z = +1
    id = view.add_keyframe(std::move(kf));
  }
  const io::FrameData frame = synthetic_frame(0, 2.f);
  // One culled feature at the image centre and one moving box in the top-left corner.
  const std::vector<cv::KeyPoint> keypoints = {cv::KeyPoint(80, 60, 7), cv::KeyPoint(140, 100, 7)};
  dyn::Detection person;
  person.box = cv::Rect2f(0, 0, 40, 30);
  artifacts.on_frame(frame, keypoints, {true, false}, {person}, {true});
  artifacts.on_keyframe(id, frame);
  map::MapView view = map.view();
  const nlohmann::json stats = artifacts.write(view);
  const auto cloud = report::read_ply(out / "dense_cloud.ply");
  ASSERT_EQ(cloud.size(), stats.at("dense_cloud_points").get<std::size_t>());
  const std::size_t grid = 40 * 30;
  EXPECT_GT(cloud.size(), grid / 2);
  EXPECT_LT(cloud.size(), grid - 50);
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const float x = cloud.xyz[3 * i], y = cloud.xyz[3 * i + 1], z = cloud.xyz[3 * i + 2];
    ASSERT_FLOAT_EQ(z, 3.f);  // depth 2 m in front of a camera at z = 1
    // Back to pixels: nothing within the margin of the culled feature, nothing inside the box.
    const float u = x / 2.f * 100 + 80, v = y / 2.f * 100 + 60;
    EXPECT_GT(std::hypot(u - 80, v - 60), 12.f - 4.f) << u << "," << v;
    EXPECT_FALSE(u < 40 && v < 30) << u << "," << v;
    EXPECT_EQ(cloud.rgb[3 * i], 220);  // red channel of the BGR (20, 120, 220) image
  }
}

}  // namespace
}  // namespace sp
