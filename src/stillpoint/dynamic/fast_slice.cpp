#include "stillpoint/dynamic/fast_slice.hpp"

#include <algorithm>
#include <cstring>
#include <opencv2/dnn.hpp>
#include <opencv2/dnn/all_layers.hpp>
#include <opencv2/dnn/layer.details.hpp>

namespace sp::dyn {
namespace {

void copy_axis(const float* src, const cv::Mat& in, float* dst, const cv::Mat& out,
               const std::vector<int>& start, const std::vector<int>& step, int axis) {
  const int n = out.size[axis];
  const std::size_t in_stride = in.step[axis] / sizeof(float);
  const std::size_t out_stride = out.step[axis] / sizeof(float);
  src += static_cast<std::size_t>(start[static_cast<std::size_t>(axis)]) * in_stride;
  const auto s = static_cast<std::size_t>(step[static_cast<std::size_t>(axis)]);
  if (axis + 1 == in.dims) {
    if (s == 1) {
      std::memcpy(dst, src, static_cast<std::size_t>(n) * sizeof(float));
    } else {
      for (int k = 0; k < n; ++k) dst[k] = src[static_cast<std::size_t>(k) * s];
    }
    return;
  }
  for (int k = 0; k < n; ++k)
    copy_axis(src + static_cast<std::size_t>(k) * s * in_stride, in,
              dst + static_cast<std::size_t>(k) * out_stride, out, start, step, axis + 1);
}

// Start of an axis range as OpenCV normalises it: negative counts from the end, clamped into the axis.
int normalised_start(int start, int n) {
  start = std::min(std::max(start, -n), n - 1);
  return start < 0 ? start + n : start;
}

class FastSliceLayer : public cv::dnn::Layer {
 public:
  FastSliceLayer(const cv::dnn::LayerParams& params, cv::Ptr<cv::dnn::Layer> shapes)
      : shapes_(std::move(shapes)) {
    setParamsFrom(params);
    const cv::dnn::DictValue& begin = params.get("begin");
    for (int i = 0; i < begin.size(); ++i) begin_.push_back(begin.get<int>(i));
    step_.assign(begin_.size(), 1);
    if (params.has("steps")) {
      const cv::dnn::DictValue& steps = params.get("steps");
      for (int i = 0; i < steps.size() && i < static_cast<int>(step_.size()); ++i)
        step_[static_cast<std::size_t>(i)] = steps.get<int>(i);
    }
  }

  bool getMemoryShapes(const std::vector<cv::dnn::MatShape>& inputs, int required_outputs,
                       std::vector<cv::dnn::MatShape>& outputs,
                       std::vector<cv::dnn::MatShape>& internals) const override {
    return shapes_->getMemoryShapes(inputs, required_outputs, outputs, internals);
  }
  bool updateMemoryShapes(const std::vector<cv::dnn::MatShape>& inputs) override {
    return shapes_->updateMemoryShapes(inputs);
  }

  void forward(cv::InputArrayOfArrays inputs_arr, cv::OutputArrayOfArrays outputs_arr,
               cv::OutputArrayOfArrays /*internals*/) override {
    std::vector<cv::Mat> inputs, outputs;
    inputs_arr.getMatVector(inputs);
    outputs_arr.getMatVector(outputs);
    CV_Assert(inputs.size() == 1 && outputs.size() == 1);
    const cv::Mat& in = inputs[0];
    cv::Mat& out = outputs[0];
    CV_Assert(in.type() == CV_32F && out.type() == CV_32F && in.dims == out.dims);
    CV_Assert(begin_.size() <= static_cast<std::size_t>(in.dims));  // OpenCV's shape rule, checked again
    std::vector<int> start(begin_.size());  // strided_slice fills the axes after these with 0 / 1
    for (std::size_t a = 0; a < start.size(); ++a)
      start[a] = normalised_start(begin_[a], in.size[static_cast<int>(a)]);
    strided_slice(in, start, step_, out);
  }

 private:
  cv::Ptr<cv::dnn::Layer> shapes_;  // OpenCV's own layer, for the output shapes
  std::vector<int> begin_, step_;
};

// Ours for a begin/end (or begin/size) slice with positive steps; OpenCV's own layer otherwise.
cv::Ptr<cv::dnn::Layer> create_slice(cv::dnn::LayerParams& params) {
  cv::Ptr<cv::dnn::Layer> own = cv::dnn::SliceLayer::create(params);
  bool covered = params.has("begin") && !params.has("slice_point") && !params.has("num_split");
  if (covered && params.has("steps")) {
    const cv::dnn::DictValue& steps = params.get("steps");
    for (int i = 0; i < steps.size(); ++i) covered = covered && steps.get<int>(i) >= 1;
  }
  if (!covered) return own;
  return cv::makePtr<FastSliceLayer>(params, own);
}

}  // namespace

void strided_slice(const cv::Mat& src, const std::vector<int>& start, const std::vector<int>& step,
                   cv::Mat& dst) {
  CV_Assert(src.type() == CV_32F && dst.type() == CV_32F && src.dims == dst.dims);
  std::vector<int> s(static_cast<std::size_t>(src.dims), 0), k(static_cast<std::size_t>(src.dims), 1);
  for (std::size_t a = 0; a < s.size(); ++a) {
    if (a < start.size()) s[a] = start[a];
    if (a < step.size()) k[a] = step[a];
    const int axis = static_cast<int>(a);
    CV_Assert(k[a] >= 1 && s[a] >= 0);
    CV_Assert(dst.size[axis] == 0 || s[a] + (dst.size[axis] - 1) * k[a] < src.size[axis]);
  }
  if (dst.total() == 0) return;
  copy_axis(src.ptr<float>(), src, dst.ptr<float>(), dst, s, k, 0);
}

bool is_fast_slice(const cv::Ptr<cv::dnn::Layer>& layer) {
  return dynamic_cast<const FastSliceLayer*>(layer.get()) != nullptr;
}

ScopedFastSlice::ScopedFastSlice() { cv::dnn::LayerFactory::registerLayer("Slice", create_slice); }

ScopedFastSlice::~ScopedFastSlice() { cv::dnn::LayerFactory::unregisterLayer("Slice"); }

}  // namespace sp::dyn
