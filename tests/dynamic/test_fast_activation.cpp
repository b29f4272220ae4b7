// The detector's vectorised sigmoid against the C library's exp, and a YOLOX-nano network built with
// it against the same network with OpenCV's own Sigmoid layer.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <vector>

#include "../support/shared_data.hpp"
#include "detector_agreement.hpp"
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
  const DetectorConfig fast = testing::yolox_nano_as_run(model);
  DetectorConfig ref = fast;
  ref.fast_sigmoid = false;
  const int boxes = testing::compare_detections(
      fast, ref, people, {"yolov5_bus.jpg", "yolov5_zidane.jpg", "darknet_person.jpg", "opencv_messi5.jpg"},
      0.01, 1e-4);
  EXPECT_GE(boxes, 4);  // the comparison covered real detections
  // OpenCV's own layer is back for networks loaded afterwards: two more reference detectors, built
  // after fast ones, agree exactly.
  EXPECT_GE(testing::compare_detections(ref, ref, people, {"yolov5_zidane.jpg"}, 0.0, 0.0), 1);
}

}  // namespace
}  // namespace sp::dyn
