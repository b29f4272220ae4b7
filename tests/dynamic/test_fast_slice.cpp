// The detector's strided-copy Slice layer against OpenCV's own Slice layer: one-layer networks over
// ranges, steps and negative indices, and YOLOX-nano (whose input block is eight step-2 slices).
#include <gtest/gtest.h>

#include <filesystem>
#include <opencv2/dnn.hpp>
#include <opencv2/imgcodecs.hpp>
#include <optional>
#include <vector>

#include "../support/shared_data.hpp"
#include "detector_agreement.hpp"
#include "stillpoint/dynamic/fast_slice.hpp"
#include "stillpoint/dynamic/yolo_detector.hpp"

namespace sp::dyn {
namespace {

struct SliceCase {
  std::vector<int> begin, end, steps;  // steps empty: none given
};

cv::Mat run_slice(const cv::Mat& input, const SliceCase& c, bool fast, bool* used_fast) {
  std::optional<ScopedFastSlice> scope;
  if (fast) scope.emplace();
  cv::dnn::LayerParams params;
  params.name = "slice";
  params.type = "Slice";
  params.set("begin", cv::dnn::DictValue::arrayInt(c.begin.data(), static_cast<int>(c.begin.size())));
  params.set("end", cv::dnn::DictValue::arrayInt(c.end.data(), static_cast<int>(c.end.size())));
  if (!c.steps.empty())
    params.set("steps", cv::dnn::DictValue::arrayInt(c.steps.data(), static_cast<int>(c.steps.size())));
  cv::dnn::Net net;
  net.addLayerToPrev(params.name, params.type, params);
  net.setPreferableBackend(cv::dnn::DNN_BACKEND_OPENCV);
  net.setInput(input);
  cv::Mat out = net.forward("slice").clone();
  *used_fast = is_fast_slice(net.getLayer(params.name));
  return out;
}

TEST(FastSlice, OneLayerNetworksMatchOpenCVsSlice) {
  const int shape[] = {2, 3, 10, 13};
  cv::Mat input(4, shape, CV_32F);
  cv::randu(input, -1.0, 1.0);
  const std::vector<SliceCase> cases = {
      {{0, 0, 0}, {-1, -1, 2147483647}, {1, 1, 2}},            // YOLOX Focus: x[..., ::2, :]
      {{0, 0, 0, 1}, {-1, -1, -1, 2147483647}, {1, 1, 1, 2}},  // x[..., 1::2]
      {{0, 1, 2, 3}, {2, 3, 9, 12}, {}},                       // plain ranges, no steps given
      {{1, 0, 1, 0}, {2, 2, 10, 13}, {1, 1, 3, 4}},            // steps that do not divide the range
      {{0, -2, -7}, {-1, -1, -2}, {1, 1, 2}},                  // negative begin and end
      {{0, 0, 5}, {-1, -1, 6}, {1, 1, 1}},                     // a single row
  };
  for (std::size_t k = 0; k < cases.size(); ++k) {
    bool fast_used = false, ref_fast = true;
    const cv::Mat fast = run_slice(input, cases[k], true, &fast_used);
    const cv::Mat ref = run_slice(input, cases[k], false, &ref_fast);
    EXPECT_TRUE(fast_used) << "case " << k;
    EXPECT_FALSE(ref_fast) << "case " << k;
    ASSERT_EQ(fast.dims, ref.dims) << "case " << k;
    for (int d = 0; d < ref.dims; ++d) ASSERT_EQ(fast.size[d], ref.size[d]) << "case " << k << " axis " << d;
    EXPECT_EQ(cv::norm(fast, ref, cv::NORM_INF), 0.0) << "case " << k;
  }
}

TEST(FastSlice, StridedSliceCopiesTheSelectedElements) {
  const int in_shape[] = {1, 2, 5, 6};
  cv::Mat in(4, in_shape, CV_32F);
  for (std::size_t i = 0; i < in.total(); ++i) in.ptr<float>()[i] = static_cast<float>(i);
  const int out_shape[] = {1, 2, 2, 3};
  cv::Mat out(4, out_shape, CV_32F);
  strided_slice(in, {0, 0, 1, 0}, {1, 1, 2, 2}, out);
  for (int c = 0; c < 2; ++c)
    for (int y = 0; y < 2; ++y)
      for (int x = 0; x < 3; ++x) {
        const int idx[] = {0, c, y, x};
        EXPECT_EQ(out.at<float>(idx), static_cast<float>(c * 30 + (1 + 2 * y) * 6 + 2 * x));
      }
  // A range reaching past the input is refused, not read out of bounds.
  cv::Mat too_big(4, std::vector<int>{1, 2, 3, 3}.data(), CV_32F);
  EXPECT_THROW(strided_slice(in, {0, 0, 1, 0}, {1, 1, 2, 2}, too_big), cv::Exception);
}

TEST(FastSlice, SplitsKeepOpenCVsLayer) {
  ScopedFastSlice scope;
  cv::dnn::LayerParams params;
  params.type = "Slice";
  params.set("axis", 1);
  const int slice_point = 2;
  params.set("slice_point", cv::dnn::DictValue::arrayInt(&slice_point, 1));
  const cv::Ptr<cv::dnn::Layer> layer = cv::dnn::LayerFactory::createLayerInstance("Slice", params);
  ASSERT_FALSE(layer.empty());
  EXPECT_FALSE(is_fast_slice(layer));
}

TEST(FastSlice, YoloxNanoUsesItAndGivesTheSameBoxes) {
  const std::filesystem::path model = SP_SHARED_DIR "/models/yolox_nano.onnx";
  const std::filesystem::path people = SP_SHARED_DIR "/data/people";
  SP_REQUIRE_SHARED(model, people);
  const DetectorConfig fast = testing::yolox_nano_as_run(model);
  DetectorConfig ref = fast;
  ref.fast_slice = false;
  const int boxes = testing::compare_detections(
      fast, ref, people, {"yolov5_bus.jpg", "yolov5_zidane.jpg", "darknet_person.jpg"}, 0.0, 0.0);
  EXPECT_GE(boxes, 3);
  // The comparison above is not vacuous: a network read with the layer in place has its eight input
  // slices as strided copies.
  ScopedFastSlice scope;
  cv::dnn::Net net = cv::dnn::readNetFromONNX(model.string());
  int fast_layers = 0;
  for (const auto& name : net.getLayerNames()) fast_layers += is_fast_slice(net.getLayer(name)) ? 1 : 0;
  EXPECT_EQ(fast_layers, 8);
}

}  // namespace
}  // namespace sp::dyn
