// The detector's vectorised sigmoid against the C library's exp, and a YOLOX-nano network built with
// it against the same network with OpenCV's own Sigmoid layer.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <vector>

#include "../support/shared_data.hpp"
#include "stillpoint/dynamic/fast_activation.hpp"
#include "stillpoint/dynamic/yolo_detector.hpp"

namespace sp::dyn {
namespace {

TEST(FastActivation, ExpMatchesTheLibraryOverTheFloatRange) {
  double worst = 0;
  for (double x = -87.0; x <= 87.0; x += 0.001) {
    const double ref = std::exp(static_cast<double>(static_cast<float>(x)));
    worst = std::max(worst, std::abs(fast_exp(static_cast<float>(x)) / ref - 1.0));
  }
  EXPECT_LT(worst, 2e-7);
  // Beyond the float range it saturates instead of producing inf / denormals.
  EXPECT_TRUE(std::isfinite(fast_exp(1000.f)));
  EXPECT_GT(fast_exp(-1000.f), 0.f);
  EXPECT_LT(fast_exp(-1000.f), 1e-37f);
}

TEST(FastActivation, SigmoidMatchesTheDefinitionInPlaceAndOutOfPlace) {
  std::vector<float> in;
  for (float x = -100.f; x <= 100.f; x += 0.0137f) in.push_back(x);
  std::vector<float> out(in.size());
  fast_sigmoid(in.data(), out.data(), in.size());
  std::vector<float> same = in;
  fast_sigmoid(same.data(), same.data(), same.size());
  for (std::size_t i = 0; i < in.size(); ++i) {
    const double ref = 1.0 / (1.0 + std::exp(-static_cast<double>(in[i])));
    ASSERT_NEAR(out[i], ref, 1e-6 * ref + 1e-30) << "x = " << in[i];
    ASSERT_EQ(same[i], out[i]);
  }
  EXPECT_GE(out.front(), 0.f);
  EXPECT_LE(out.back(), 1.f);
}

TEST(FastActivation, YoloxNanoGivesTheSameBoxesAsWithOpenCVsSigmoid) {
  const std::filesystem::path model = SP_SHARED_DIR "/models/yolox_nano.onnx";
  const std::filesystem::path people = SP_SHARED_DIR "/data/people";
  SP_REQUIRE_SHARED(model, people);
  DetectorConfig fast = DetectorConfig::for_model(model);
  fast.fit_input_to_image(320, 640, 480);
  DetectorConfig ref = fast;
  fast.fast_sigmoid = true;
  ref.fast_sigmoid = false;
  YoloDetector det_fast(fast), det_ref(ref);
  int boxes = 0;
  for (const char* file :
       {"yolov5_bus.jpg", "yolov5_zidane.jpg", "darknet_person.jpg", "opencv_messi5.jpg"}) {
    const cv::Mat img = cv::imread((people / file).string(), cv::IMREAD_COLOR);
    ASSERT_FALSE(img.empty()) << file;
    const Detections a = det_fast.detect(img), b = det_ref.detect(img);
    ASSERT_EQ(a.items.size(), b.items.size()) << file;
    for (std::size_t i = 0; i < a.items.size(); ++i) {
      EXPECT_NEAR(a.items[i].box.x, b.items[i].box.x, 0.01) << file;
      EXPECT_NEAR(a.items[i].box.y, b.items[i].box.y, 0.01) << file;
      EXPECT_NEAR(a.items[i].box.width, b.items[i].box.width, 0.01) << file;
      EXPECT_NEAR(a.items[i].box.height, b.items[i].box.height, 0.01) << file;
      EXPECT_NEAR(a.items[i].score, b.items[i].score, 1e-4) << file;
    }
    boxes += static_cast<int>(a.items.size());
  }
  EXPECT_GE(boxes, 4);  // the comparison covered real detections
  // OpenCV's own layer is back for networks loaded afterwards: a third detector, built without the
  // fast layer, agrees with the first reference one exactly.
  YoloDetector det_ref2(ref);
  const cv::Mat img = cv::imread((people / "yolov5_zidane.jpg").string(), cv::IMREAD_COLOR);
  const Detections b = det_ref.detect(img), c = det_ref2.detect(img);
  ASSERT_EQ(b.items.size(), c.items.size());
  for (std::size_t i = 0; i < b.items.size(); ++i) EXPECT_EQ(b.items[i].score, c.items[i].score);
}

}  // namespace
}  // namespace sp::dyn
