// YOLOv7-tiny, the paper's detector, as an ONNX graph with random weights in the official export layout
// (scripts/make_yolov7_tiny_onnx.py, generated here at test time into the build tree): the project's
// loader and yolov7 decoder read it through cv::dnn. No trained weights exist here, so nothing is
// asserted about what it detects, only the format: shape, decoding, finite boxes inside the image.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <opencv2/dnn.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

#include "stillpoint/dynamic/decoders.hpp"
#include "stillpoint/dynamic/yolo_detector.hpp"

namespace sp::dyn {
namespace {

const std::filesystem::path kScript =
    std::filesystem::path(SP_SOURCE_DIR) / "scripts" / "make_yolov7_tiny_onnx.py";

// Generates the model once per test binary; empty path (and a reason) when python3-onnx is missing.
const std::filesystem::path& model_file(std::string& why) {
  static std::string reason;
  static const std::filesystem::path file = [] {
    const auto dir = std::filesystem::path(SP_TEST_TMP_DIR) / "yolov7_tiny";
    std::filesystem::create_directories(dir);
    const auto out = dir / "yolov7_tiny_random.onnx";
    const std::string python = SP_PYTHON3;
    if (std::system((python + " -c 'import onnx, numpy' 2>/dev/null").c_str()) != 0) {
      reason = python + " cannot import onnx/numpy (Debian: apt-get install python3-onnx, scripts/setup.sh)";
      return std::filesystem::path();
    }
    const std::string cmd = python + " " + kScript.string() + " --out " + out.string() + " --seed 7";
    if (std::system(cmd.c_str()) != 0) {
      reason = "failed: " + cmd;
      return std::filesystem::path();
    }
    return out;
  }();
  why = reason;
  return file;
}

// Skips without python3-onnx on a developer machine; on CI (CI set) that is a failure.
#define SP_REQUIRE_YOLOV7_MODEL(var)                                                     \
  std::string why_;                                                                      \
  const std::filesystem::path var = model_file(why_);                                    \
  if (var.empty()) {                                                                     \
    if (std::getenv("CI") == nullptr && why_.find("cannot import") != std::string::npos) \
      GTEST_SKIP() << why_;                                                              \
    FAIL() << why_;                                                                      \
  }

cv::Mat test_image() {
  // A textured 640x480 BGR image (fixed seed): random weights respond to anything.
  cv::Mat img(480, 640, CV_8UC3);
  cv::RNG rng(11);
  rng.fill(img, cv::RNG::UNIFORM, 0, 255);
  cv::GaussianBlur(img, img, cv::Size(7, 7), 2.0);
  cv::rectangle(img, cv::Rect(200, 100, 120, 300), cv::Scalar(30, 60, 200), cv::FILLED);
  return img;
}

TEST(Yolov7TinyGraph, OfficialLayoutThroughCvDnn) {
  SP_REQUIRE_YOLOV7_MODEL(model);
  const DetectorConfig cfg = DetectorConfig::for_model(model);
  // The loader's choice for a non-YOLOX .onnx: the YOLOv7 export's input convention.
  EXPECT_EQ(cfg.decoder, "yolov7");
  EXPECT_EQ(cfg.input_width, 640);
  EXPECT_EQ(cfg.input_height, 640);
  EXPECT_TRUE(cfg.swap_rb);
  EXPECT_NEAR(cfg.scale, 1.0 / 255.0, 1e-12);

  cv::dnn::Net net = cv::dnn::readNetFromONNX(model.string());
  ASSERT_FALSE(net.empty());
  InputTransform tf;
  const cv::Mat img = test_image();
  net.setInput(make_input_blob(img, cfg, tf));
  const cv::Mat out = net.forward();
  ASSERT_EQ(out.dims, 3);
  EXPECT_EQ(out.size[0], 1);
  EXPECT_EQ(out.size[1], 25200);  // 3 anchors x (80^2 + 40^2 + 20^2) cells
  EXPECT_EQ(out.size[2], 85);
  EXPECT_TRUE(cv::checkRange(out));  // no NaN / Inf
  DetectorConfig auto_cfg = cfg;
  auto_cfg.decoder = "auto";  // auto at 640: 3x the YOLOX grid count -> the YOLOv5/v7 layout
  EXPECT_EQ(resolve_decoder(auto_cfg, out.size[1]), "yolov5");

  // Row layout of the export: stride 8 first, anchor-major, then grid row, then column; cx, cy in input
  // pixels within [-0.5, 1.5] cells of their own cell, w, h within 4x their anchor.
  const cv::Mat rows(out.size[1], out.size[2], CV_32F, const_cast<float*>(out.ptr<float>()));
  const auto cell_check = [&](int row, float gx, float gy, float stride, float aw, float ah) {
    const float* r = rows.ptr<float>(row);
    EXPECT_GE(r[0], (gx - 0.5f) * stride - 1e-3f) << row;
    EXPECT_LE(r[0], (gx + 1.5f) * stride + 1e-3f) << row;
    EXPECT_GE(r[1], (gy - 0.5f) * stride - 1e-3f) << row;
    EXPECT_LE(r[1], (gy + 1.5f) * stride + 1e-3f) << row;
    EXPECT_GT(r[2], 0.f);
    EXPECT_LE(r[2], 4.f * aw + 1e-3f) << row;
    EXPECT_LE(r[3], 4.f * ah + 1e-3f) << row;
    for (int c = 4; c < 85; ++c) {
      EXPECT_GE(r[c], 0.f);
      EXPECT_LE(r[c], 1.f);
    }
  };
  cell_check(0, 0, 0, 8, 10, 13);                   // P3, anchor 0, cell (0, 0)
  cell_check(1, 1, 0, 8, 10, 13);                   // next column
  cell_check(80, 0, 1, 8, 10, 13);                  // next row
  cell_check(6400, 0, 0, 8, 16, 30);                // anchor 1
  cell_check(19200, 0, 0, 16, 30, 61);              // P4 starts after 3 x 80^2 rows
  cell_check(19200 + 3 * 1600, 0, 0, 32, 116, 90);  // P5 after 3 x 40^2 more
  cell_check(25199, 19, 19, 32, 373, 326);          // last row: P5, anchor 2, cell (19, 19)

  // The decoder on this output: the threshold is set so that the 300 best rows pass (random weights
  // score low everywhere), then the mapping back to the image and NMS.
  std::vector<float> scores;
  for (int i = 0; i < rows.rows; ++i) {
    const float* r = rows.ptr<float>(i);
    scores.push_back(r[4] * *std::max_element(r + 5, r + 85));
  }
  std::nth_element(scores.begin(), scores.begin() + 299, scores.end(), std::greater<>());
  const float threshold = scores[299];
  const auto decoded = decode_yolov5(out, threshold);
  EXPECT_GE(decoded.size(), 300u);
  const auto mapped = map_to_image(decoded, tf);
  const auto kept = nms_per_class(mapped, 0.45f);
  ASSERT_FALSE(kept.empty());
  for (const auto& d : kept) {
    EXPECT_TRUE(std::isfinite(d.box.x) && std::isfinite(d.box.y) && std::isfinite(d.box.width) &&
                std::isfinite(d.box.height));
    EXPECT_GE(d.box.x, 0.f);
    EXPECT_GE(d.box.y, 0.f);
    EXPECT_LE(d.box.x + d.box.width, 640.f + 1e-3f);
    EXPECT_LE(d.box.y + d.box.height, 480.f + 1e-3f);
    EXPECT_GE(d.score, threshold);
  }

  // The project's detector end to end (loader, preprocessing, decoder, NMS), all classes reported.
  DetectorConfig all = cfg;
  all.dynamic_classes.clear();
  all.conf_threshold = threshold;
  YoloDetector det(all);
  const Detections d = det.detect(img);
  EXPECT_EQ(det.decoder(), "yolov5");  // the yolov7 export is read by the YOLOv5-style decoder
  EXPECT_GT(d.inference_ms, 0.0);
  ASSERT_FALSE(d.items.empty());
  for (const auto& it : d.items) {
    EXPECT_TRUE(std::isfinite(it.box.x) && std::isfinite(it.box.width));
    EXPECT_LE(it.box.x + it.box.width, 640.f + 1e-3f);
    EXPECT_LE(it.box.y + it.box.height, 480.f + 1e-3f);
  }
}

}  // namespace
}  // namespace sp::dyn
