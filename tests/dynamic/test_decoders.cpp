// Decoders, preprocessing geometry and NMS on hand-made tensors with known boxes.
#include <gtest/gtest.h>

#include <cmath>

#include "stillpoint/common/error.hpp"
#include "stillpoint/dynamic/decoders.hpp"

namespace sp::dyn {
namespace {

constexpr int kCols = 85;

cv::Mat rows3d(int n) {
  const int sizes[] = {1, n, kCols};
  return cv::Mat(3, sizes, CV_32F, cv::Scalar(0));
}
float* row_ptr(cv::Mat& m, int i) { return m.ptr<float>(0) + static_cast<std::ptrdiff_t>(i) * kCols; }

void expect_box(const cv::Rect2f& b, float x, float y, float w, float h) {
  EXPECT_NEAR(b.x, x, 1e-3);
  EXPECT_NEAR(b.y, y, 1e-3);
  EXPECT_NEAR(b.width, w, 1e-3);
  EXPECT_NEAR(b.height, h, 1e-3);
}

TEST(Decoders, Yolov5RowsAreCentreSizeInInputPixels) {
  cv::Mat out = rows3d(3);
  float* r0 = row_ptr(out, 0);
  r0[0] = 100, r0[1] = 50, r0[2] = 40, r0[3] = 20, r0[4] = 0.9f, r0[5 + 0] = 0.8f, r0[5 + 3] = 0.1f;
  float* r1 = row_ptr(out, 1);  // objectness too low
  r1[0] = 10, r1[1] = 10, r1[2] = 5, r1[3] = 5, r1[4] = 0.2f, r1[5] = 1.0f;
  float* r2 = row_ptr(out, 2);  // class 2 wins
  r2[0] = 200, r2[1] = 100, r2[2] = 10, r2[3] = 30, r2[4] = 0.9f, r2[5] = 0.1f, r2[5 + 2] = 0.9f;
  const auto d = decode_yolov5(out, 0.35f);
  ASSERT_EQ(d.size(), 2u);
  expect_box(d[0].box, 80, 40, 40, 20);
  EXPECT_EQ(d[0].class_id, 0);
  EXPECT_NEAR(d[0].score, 0.72f, 1e-5);
  expect_box(d[1].box, 195, 85, 10, 30);
  EXPECT_EQ(d[1].class_id, 2);
  EXPECT_NEAR(d[1].score, 0.81f, 1e-5);
}

TEST(Decoders, YoloxGridAndStrideDecoding) {
  // 64x64 input: 8x8 cells at stride 8, 4x4 at 16, 2x2 at 32 = 84 rows.
  cv::Mat out = rows3d(84);
  float* r = row_ptr(out, 64 + 2 * 4 + 1);  // stride 16, gx = 1, gy = 2
  r[0] = 0.5f, r[1] = 0.25f, r[2] = std::log(2.f), r[3] = std::log(3.f), r[4] = 0.9f, r[5] = 0.9f;
  float* s = row_ptr(out, 84 - 1);  // stride 32, gx = 1, gy = 1, class 7
  s[0] = 0, s[1] = 0, s[2] = 0, s[3] = 0, s[4] = 0.8f, s[5 + 7] = 0.5f;
  const auto d = decode_yolox(out, 64, 64, 0.35f);
  ASSERT_EQ(d.size(), 2u);
  expect_box(d[0].box, 24 - 16, 36 - 24, 32, 48);
  EXPECT_NEAR(d[0].score, 0.81f, 1e-5);
  expect_box(d[1].box, 32 - 16, 32 - 16, 32, 32);
  EXPECT_EQ(d[1].class_id, 7);
  EXPECT_THROW(decode_yolox(out, 96, 64, 0.35f), Error);  // grid count mismatch
}

TEST(Decoders, DarknetNormalisedRowsOverSeveralOutputs) {
  cv::Mat a(2, kCols, CV_32F, cv::Scalar(0)), b(1, kCols, CV_32F, cv::Scalar(0));
  float* r = a.ptr<float>(1);
  r[0] = 0.5f, r[1] = 0.25f, r[2] = 0.1f, r[3] = 0.2f, r[4] = 0.9f, r[5] = 0.7f;
  float* q = b.ptr<float>(0);
  q[0] = 0.1f, q[1] = 0.1f, q[2] = 0.05f, q[3] = 0.05f, q[4] = 0.9f, q[5 + 16] = 0.3f;  // below threshold
  const auto d = decode_darknet({a, b}, 320, 320, 0.35f);
  ASSERT_EQ(d.size(), 1u);
  expect_box(d[0].box, 144, 48, 32, 64);
  EXPECT_NEAR(d[0].score, 0.7f, 1e-6);
}

TEST(Decoders, LetterboxMapsBackAndPadsWith114) {
  DetectorConfig cfg;  // 416x416 letterbox, scale 1
  cv::Mat img(480, 640, CV_8UC3, cv::Scalar(10, 20, 30));
  InputTransform tf;
  const cv::Mat blob = make_input_blob(img, cfg, tf);
  ASSERT_EQ(blob.dims, 4);
  EXPECT_EQ(blob.size[2], 416);
  EXPECT_EQ(blob.size[3], 416);
  EXPECT_NEAR(tf.sx, 0.65, 1e-9);
  const float* plane0 = blob.ptr<float>(0, 0);
  EXPECT_FLOAT_EQ(plane0[10 * 416 + 10], 10.f);    // content at the top-left, B first (no swap)
  EXPECT_FLOAT_EQ(plane0[400 * 416 + 10], 114.f);  // below 480 * 0.65 = 312 rows: padding
  const auto m = map_to_image({{cv::Rect2f(65, 65, 130, 65), 0, 0.9f}}, tf);
  ASSERT_EQ(m.size(), 1u);
  expect_box(m[0].box, 100, 100, 200, 100);
}

TEST(Decoders, PlainResizeMappingAndClipping) {
  DetectorConfig cfg;
  cfg.letterbox = false;
  cfg.input_width = cfg.input_height = 320;
  cfg.swap_rb = true;
  cfg.scale = 1.0 / 255;
  cv::Mat img(480, 640, CV_8UC3, cv::Scalar(0, 0, 255));
  InputTransform tf;
  const cv::Mat blob = make_input_blob(img, cfg, tf);
  EXPECT_FLOAT_EQ(blob.ptr<float>(0, 0)[0], 1.f);  // red first after swap, scaled to 1
  EXPECT_NEAR(tf.sx, 0.5, 1e-9);
  EXPECT_NEAR(tf.sy, 320.0 / 480, 1e-9);
  const auto m =
      map_to_image({{cv::Rect2f(300, -20, 40, 60), 0, 0.9f}, {cv::Rect2f(330, 0, 5, 5), 0, 0.9f}}, tf);
  ASSERT_EQ(m.size(), 1u);  // the second lies outside the image
  expect_box(m[0].box, 600, 0, 40, 60);
}

TEST(Decoders, ClassAwareNms) {
  std::vector<Detection> d = {{cv::Rect2f(0, 0, 100, 100), 0, 0.6f},
                              {cv::Rect2f(5, 5, 100, 100), 0, 0.9f},
                              {cv::Rect2f(5, 5, 100, 100), 3, 0.5f},
                              {cv::Rect2f(300, 300, 50, 50), 0, 0.4f}};
  const auto k = nms_per_class(d, 0.45f);
  ASSERT_EQ(k.size(), 3u);
  EXPECT_FLOAT_EQ(k[0].score, 0.9f);
  EXPECT_EQ(k[1].class_id, 3);  // other class survives the overlap
  EXPECT_FLOAT_EQ(k[2].score, 0.4f);
  EXPECT_NEAR(iou(cv::Rect2f(0, 0, 10, 10), cv::Rect2f(5, 0, 10, 10)), 50.f / 150.f, 1e-6);
}

// A box within the margin of any edge reaches the border; one clear of all four does not.
TEST(Decoders, ReachesBorderOnEachEdgeWithinTheMargin) {
  const cv::Size img(640, 480);
  EXPECT_FALSE(reaches_border({100, 100, 200, 200}, img, 4.f));
  EXPECT_TRUE(reaches_border({3, 100, 50, 50}, img, 4.f));     // left
  EXPECT_TRUE(reaches_border({100, 2, 50, 50}, img, 4.f));     // top
  EXPECT_TRUE(reaches_border({600, 100, 37, 50}, img, 4.f));   // right: 637 >= 636
  EXPECT_TRUE(reaches_border({100, 400, 50, 77}, img, 4.f));   // bottom: 477 >= 476
  EXPECT_FALSE(reaches_border({600, 100, 35, 50}, img, 4.f));  // right: 635 < 636
  EXPECT_FALSE(reaches_border({5, 5, 50, 50}, img, 4.f));
  EXPECT_TRUE(reaches_border({5, 5, 50, 50}, img, 5.f));
}

// Weak boxes survive only at the border; strong boxes survive anywhere.
TEST(Decoders, WeakBoxesAreKeptOnlyWhereTheyReachTheBorder) {
  std::vector<Detection> d{{{0, 100, 80, 300}, 0, 0.28f},     // weak, cut by the left edge: kept
                           {{200, 100, 80, 300}, 0, 0.28f},   // weak, in full view: dropped
                           {{300, 100, 80, 300}, 0, 0.50f},   // strong, in full view: kept
                           {{560, 100, 80, 300}, 0, 0.30f}};  // weak, reaches the right edge: kept
  drop_weak_interior(d, {640, 480}, 0.35f, 4.f);
  ASSERT_EQ(d.size(), 3U);
  EXPECT_FLOAT_EQ(d[0].box.x, 0.f);
  EXPECT_FLOAT_EQ(d[1].box.x, 300.f);
  EXPECT_FLOAT_EQ(d[2].box.x, 560.f);
}

TEST(Decoders, ResolveAutoFromShapeAndFileType) {
  DetectorConfig cfg;
  cfg.model = "x.onnx";
  EXPECT_EQ(resolve_decoder(cfg, 3549), "yolox");
  EXPECT_EQ(resolve_decoder(cfg, 3 * 3549), "yolov5");
  EXPECT_THROW(resolve_decoder(cfg, 1000), Error);
  cfg.decoder = "yolov7";
  EXPECT_EQ(resolve_decoder(cfg, 1000), "yolov5");
  cfg.decoder = "auto";
  cfg.model = "net.cfg";
  EXPECT_EQ(resolve_decoder(cfg, 1000), "darknet");
}

}  // namespace
}  // namespace sp::dyn
