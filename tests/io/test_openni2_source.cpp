// The live-camera source without a camera: the pure conversion (depth mm -> m, RGB -> BGR, µs -> s),
// timestamp pairing, FOV intrinsics, FakeSource, and the error when no device is plugged in.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "stillpoint/common/error.hpp"
#include "stillpoint/io/fake_source.hpp"
#include "stillpoint/io/openni2_source.hpp"

namespace sp::io {
namespace {

CameraConfig small_camera(int w = 4, int h = 3) {
  CameraConfig c;
  c.intrinsics.width = w;
  c.intrinsics.height = h;
  c.intrinsics.fx = c.intrinsics.fy = 500;
  c.intrinsics.cx = w / 2.0;
  c.intrinsics.cy = h / 2.0;
  c.depth_min = 0.1;
  c.depth_max = 8.0;
  return c;
}

RawColourFrame colour_at(std::uint64_t us, int w = 4, int h = 3) {
  RawColourFrame f;
  f.timestamp_us = us;
  f.rgb = cv::Mat(h, w, CV_8UC3, cv::Scalar(10, 20, 30));
  return f;
}

RawDepthFrame depth_at(std::uint64_t us, int w = 4, int h = 3) {
  RawDepthFrame f;
  f.timestamp_us = us;
  f.depth = cv::Mat(h, w, CV_16UC1, cv::Scalar(1000));
  return f;
}

TEST(OpenNI2Convert, DepthMillimetresToMetresColourRgbToBgrStampsMicrosecondsToSeconds) {
  const CameraConfig cam = small_camera();
  // Device buffers with padded rows (stride > row), as OpenNI may deliver.
  const std::size_t cstride = 4 * 3 + 4;
  std::vector<std::uint8_t> rgb(cstride * 3, 0);
  rgb[0] = 200;                  // R of pixel (0, 0)
  rgb[1] = 100;                  // G
  rgb[2] = 50;                   // B
  rgb[cstride + 3 * 2 + 0] = 7;  // R of pixel (row 1, col 2)
  const std::size_t dstride_px = 6;
  std::vector<std::uint16_t> depth(dstride_px * 3, 0);
  depth[0] = 1234;               // 1.234 m
  depth[1] = 50;                 // 5 cm: closer than depth_min -> invalid
  depth[2] = 9000;               // 9 m: beyond depth_max -> invalid
  depth[dstride_px + 3] = 8000;  // exactly depth_max: kept
  const auto c = copy_colour_buffer(rgb.data(), 4, 3, cstride, 1'305'031'102'175'304ULL);
  const auto d = copy_depth_buffer(depth.data(), 4, 3, dstride_px * 2, 1'305'031'102'160'407ULL);
  const FrameData f = convert_openni_frames(c, d, cam, 7);
  EXPECT_EQ(f.index, 7u);
  EXPECT_NEAR(f.stamp, 1305031102.175304, 1e-6);
  EXPECT_NEAR(f.depth_stamp, 1305031102.160407, 1e-6);
  ASSERT_EQ(f.bgr.type(), CV_8UC3);
  ASSERT_EQ(f.depth.type(), CV_32FC1);
  EXPECT_EQ(f.bgr.size(), cv::Size(4, 3));
  EXPECT_EQ(f.bgr.at<cv::Vec3b>(0, 0), cv::Vec3b(50, 100, 200));
  EXPECT_EQ(f.bgr.at<cv::Vec3b>(1, 2)[2], 7);
  EXPECT_EQ(f.bgr.at<cv::Vec3b>(1, 2)[0], 0);
  EXPECT_FLOAT_EQ(f.depth.at<float>(0, 0), 1.234f);
  EXPECT_EQ(f.depth.at<float>(0, 1), 0.0f);
  EXPECT_EQ(f.depth.at<float>(0, 2), 0.0f);
  EXPECT_FLOAT_EQ(f.depth.at<float>(1, 3), 8.0f);
  EXPECT_EQ(f.depth.at<float>(2, 0), 0.0f);  // no reading stays invalid
}

TEST(OpenNI2Convert, HundredMicrometreDepthUnit) {
  std::vector<std::uint16_t> depth(12, 12345);
  const auto d = copy_depth_buffer(depth.data(), 4, 3, 8, 0, 1e-4);
  const FrameData f = convert_openni_frames(colour_at(0), d, small_camera(), 0);
  EXPECT_FLOAT_EQ(f.depth.at<float>(2, 3), 1.2345f);
}

TEST(OpenNI2Convert, CopiedFramesDoNotAliasTheDeviceBuffer) {
  std::vector<std::uint8_t> rgb(4 * 3 * 3, 1);
  const auto c = copy_colour_buffer(rgb.data(), 4, 3, 12, 0);
  rgb[0] = 99;  // the device reuses its buffer for the next frame
  EXPECT_EQ(c.rgb.at<cv::Vec3b>(0, 0)[0], 1);
}

TEST(OpenNI2Convert, RejectsBadBuffersAndSizes) {
  std::vector<std::uint8_t> buf(64, 0);
  EXPECT_THROW(copy_colour_buffer(nullptr, 4, 3, 12, 0), Error);
  EXPECT_THROW(copy_colour_buffer(buf.data(), 0, 3, 12, 0), Error);
  EXPECT_THROW(copy_colour_buffer(buf.data(), 4, 3, 11, 0), Error);  // stride shorter than a row
  EXPECT_THROW(copy_depth_buffer(buf.data(), 4, 3, 7, 0), Error);
  EXPECT_THROW(copy_depth_buffer(buf.data(), 4, 3, 9, 0), Error);  // odd stride
  EXPECT_THROW(copy_depth_buffer(buf.data(), 4, 3, 8, 0, 0.0), Error);
  // A frame whose size is not the configured camera's.
  EXPECT_THROW(convert_openni_frames(colour_at(0, 5, 3), depth_at(0), small_camera(), 0), Error);
  EXPECT_THROW(convert_openni_frames(colour_at(0), depth_at(0, 4, 2), small_camera(), 0), Error);
  RawDepthFrame wrong_type = depth_at(0);
  wrong_type.depth = cv::Mat(3, 4, CV_32FC1, cv::Scalar(1));
  EXPECT_THROW(convert_openni_frames(colour_at(0), wrong_type, small_camera(), 0), Error);
  try {
    convert_openni_frames(colour_at(0, 8, 6), depth_at(0, 8, 6), small_camera(), 0);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("8x6"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("4x3"), std::string::npos) << e.what();
  }
}

TEST(TimestampPairer, PairsNearestStampsAndDropsFramesThatCanNoLongerPair) {
  TimestampPairer p(0.02);
  // Colour at 30 Hz; depth offset by 5 ms, one depth frame missing (the one near 66.7 ms).
  for (std::uint64_t us : {0ULL, 33333ULL, 66667ULL, 100000ULL}) p.add_colour(colour_at(us));
  for (std::uint64_t us : {5000ULL, 38333ULL, 105000ULL}) p.add_depth(depth_at(us));
  std::vector<std::pair<std::uint64_t, std::uint64_t>> pairs;
  while (auto pr = p.pop_pair()) pairs.emplace_back(pr->first.timestamp_us, pr->second.timestamp_us);
  ASSERT_EQ(pairs.size(), 3u);
  EXPECT_EQ(pairs[0], (std::pair<std::uint64_t, std::uint64_t>{0, 5000}));
  EXPECT_EQ(pairs[1], (std::pair<std::uint64_t, std::uint64_t>{33333, 38333}));
  EXPECT_EQ(pairs[2], (std::pair<std::uint64_t, std::uint64_t>{100000, 105000}));
  EXPECT_EQ(p.dropped(), 1u);  // colour 66667 never had a depth partner
  EXPECT_EQ(p.pending_colour() + p.pending_depth(), 0u);
}

TEST(TimestampPairer, WaitsForThePartnerAndPrefersTheNearerDepth) {
  TimestampPairer p(0.02);
  p.add_colour(colour_at(100000));
  EXPECT_FALSE(p.pop_pair().has_value());  // no depth yet: keep the colour frame
  EXPECT_EQ(p.pending_colour(), 1u);
  p.add_depth(depth_at(85000));   // 15 ms away
  p.add_depth(depth_at(101000));  // 1 ms away: the better partner
  const auto pr = p.pop_pair();
  ASSERT_TRUE(pr.has_value());
  EXPECT_EQ(pr->second.timestamp_us, 101000u);
  EXPECT_EQ(p.dropped(), 1u);
}

TEST(TimestampPairer, StampGoingBackwardsRestartsPairing) {
  TimestampPairer p(0.02);
  p.add_colour(colour_at(5'000'000));
  p.add_colour(colour_at(1000));  // device restarted its clock
  p.add_depth(depth_at(2000));
  const auto pr = p.pop_pair();
  ASSERT_TRUE(pr.has_value());
  EXPECT_EQ(pr->first.timestamp_us, 1000u);
  EXPECT_EQ(p.dropped(), 1u);
}

TEST(TimestampPairer, BufferIsBoundedWhenOneStreamStalls) {
  TimestampPairer p(0.02, 4);
  for (int i = 0; i < 10; ++i) p.add_colour(colour_at(static_cast<std::uint64_t>(i) * 33333));
  EXPECT_EQ(p.pending_colour(), 4u);
  EXPECT_EQ(p.dropped(), 6u);
}

TEST(OpenNI2Intrinsics, FromFieldOfView) {
  // Kinect v1 colour: 62.0 x 48.6 degrees -> fx ~ 532.6, fy ~ 531.5.
  const double deg = M_PI / 180.0;
  const CameraConfig c = intrinsics_from_fov(640, 480, 62.0 * deg, 48.6 * deg);
  EXPECT_NEAR(c.intrinsics.fx, 320.0 / std::tan(31.0 * deg), 1e-9);
  EXPECT_NEAR(c.intrinsics.fx, 532.6, 0.5);
  EXPECT_NEAR(c.intrinsics.fy, 531.5, 0.5);
  EXPECT_DOUBLE_EQ(c.intrinsics.cx, 320.0);
  EXPECT_DOUBLE_EQ(c.intrinsics.cy, 240.0);
  EXPECT_DOUBLE_EQ(c.depth_factor, 1000.0);
  EXPECT_THROW(intrinsics_from_fov(640, 480, 0.0, 1.0), Error);
  EXPECT_THROW(intrinsics_from_fov(640, 480, 1.0, M_PI), Error);
}

TEST(FakeSource, ServesFramesInOrderThenEnds) {
  const CameraConfig cam = small_camera(32, 24);
  std::vector<FrameData> frames;
  for (std::size_t i = 0; i < 3; ++i)
    frames.push_back(make_synthetic_frame(cam, i, 0.1 * static_cast<double>(i)));
  FakeSource src(cam, std::move(frames), 2);
  src.push(make_synthetic_frame(cam, 3, 0.3, 1.5));
  EXPECT_EQ(src.size_hint(), 4u);
  EXPECT_EQ(src.skipped_frames(), 2u);
  EXPECT_EQ(src.camera().intrinsics.width, 32);
  for (std::size_t i = 0; i < 4; ++i) {
    const auto f = src.next();
    ASSERT_TRUE(f.has_value());
    EXPECT_EQ(f->index, i);
    EXPECT_EQ(f->bgr.size(), cv::Size(32, 24));
  }
  EXPECT_FALSE(src.next().has_value());
  EXPECT_EQ(src.served(), 4u);
  // Synthetic frames are deterministic in the seed.
  const auto a = make_synthetic_frame(cam, 0, 0, 2.0, 5);
  const auto b = make_synthetic_frame(cam, 0, 0, 2.0, 5);
  EXPECT_EQ(cv::norm(a.bgr, b.bgr, cv::NORM_L1), 0.0);
  EXPECT_FLOAT_EQ(a.depth.at<float>(3, 3), 2.0f);
}

TEST(FakeSource, CarriesConvertedCameraFrames) {
  // The camera path end to end, without the camera: raw frames -> pairer -> conversion -> FakeSource.
  const CameraConfig cam = small_camera();
  TimestampPairer p(0.02);
  FakeSource src(cam);
  for (std::uint64_t i = 0; i < 5; ++i) {
    p.add_colour(colour_at(i * 33333));
    p.add_depth(depth_at(i * 33333 + 2000));
    while (auto pr = p.pop_pair())
      src.push(convert_openni_frames(pr->first, pr->second, cam, src.size_hint()));
  }
  ASSERT_EQ(src.size_hint(), 5u);
  double last = -1;
  while (auto f = src.next()) {
    EXPECT_GT(f->stamp, last);
    last = f->stamp;
    EXPECT_FLOAT_EQ(f->depth.at<float>(1, 1), 1.0f);
    EXPECT_EQ(f->bgr.at<cv::Vec3b>(0, 0), cv::Vec3b(30, 20, 10));
  }
  EXPECT_NEAR(last, 4 * 0.033333, 1e-9);
}

TEST(OpenNI2Source, NoDeviceGivesAClearError) {
  try {
    auto src = open_openni2_camera(small_camera(640, 480));
    GTEST_SKIP() << "an OpenNI2 device is plugged in";
  } catch (const Error& e) {
    const std::string msg = e.what();
    if (openni2_available()) {
      EXPECT_NE(
          msg.find("no OpenNI2 device found; is the camera plugged in and are its udev rules installed?"),
          std::string::npos)
          << msg;
    } else {
      EXPECT_NE(msg.find("built without OpenNI2"), std::string::npos) << msg;
    }
  }
}

TEST(OpenNI2Source, MissingRecordingNamesTheUri) {
  OpenNI2Options o;
  o.uri = "/nonexistent/recording.oni";
  o.camera = small_camera(640, 480);
  try {
    auto src = open_openni2_camera(o);
    FAIL() << "opened a recording that does not exist";
  } catch (const Error& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(openni2_available() ? "/nonexistent/recording.oni" : "built without OpenNI2"),
              std::string::npos)
        << msg;
  }
}

}  // namespace
}  // namespace sp::io
