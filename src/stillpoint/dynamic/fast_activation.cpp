#include "stillpoint/dynamic/fast_activation.hpp"

#include <cstdint>
#include <cstring>
#include <opencv2/dnn.hpp>
#include <opencv2/dnn/layer.details.hpp>
#include <vector>

namespace sp::dyn {
namespace {

// exp(x) = 2^n * e^r with n = round(x / ln 2) and r = x - n ln 2 in [-ln2/2, ln2/2]: ln 2 split in
// two parts (Cody-Waite) so that r stays exact for |x| up to 87, e^r by Cephes' degree-7 minimax
// polynomial, 2^n added to the exponent bits. Branch-free float code (the file is built with
// -fno-trapping-math so the clamps become min/max instructions) for the loop below to vectorise.
inline float exp_approx(float x) {
  x = x < -87.f ? -87.f : (x > 87.f ? 87.f : x);
  const float n = (x * 1.44269504089f + 12582912.f) - 12582912.f;  // round: 1.5 * 2^23 drops the fraction
  float r = x - n * 0.693359375f;
  r = r - n * -2.12194440e-4f;
  float p = 1.9875691500e-4f;
  p = p * r + 1.3981999507e-3f;
  p = p * r + 8.3334519073e-3f;
  p = p * r + 4.1665795894e-2f;
  p = p * r + 1.6666665459e-1f;
  p = p * r + 5.0000001201e-1f;
  p = p * r * r + r + 1.f;
  std::int32_t bits = 0;
  std::memcpy(&bits, &p, sizeof bits);
  bits += static_cast<std::int32_t>(n) * (1 << 23);
  float out = 0;
  std::memcpy(&out, &bits, sizeof out);
  return out;
}

class FastSigmoidLayer : public cv::dnn::Layer {
 public:
  explicit FastSigmoidLayer(const cv::dnn::LayerParams& params) { setParamsFrom(params); }
  static cv::Ptr<cv::dnn::Layer> create(cv::dnn::LayerParams& params) {
    return cv::makePtr<FastSigmoidLayer>(params);
  }
  // Same shapes out as in; true = may run in place (as OpenCV's own activation layers).
  bool getMemoryShapes(const std::vector<cv::dnn::MatShape>& inputs, int /*required_outputs*/,
                       std::vector<cv::dnn::MatShape>& outputs,
                       std::vector<cv::dnn::MatShape>& /*internals*/) const override {
    outputs = inputs;
    return true;
  }
  void forward(cv::InputArrayOfArrays inputs_arr, cv::OutputArrayOfArrays outputs_arr,
               cv::OutputArrayOfArrays /*internals*/) override {
    std::vector<cv::Mat> inputs, outputs;
    inputs_arr.getMatVector(inputs);
    outputs_arr.getMatVector(outputs);
    for (std::size_t k = 0; k < inputs.size() && k < outputs.size(); ++k) {
      CV_Assert(inputs[k].type() == CV_32F && inputs[k].isContinuous() && outputs[k].isContinuous());
      fast_sigmoid(inputs[k].ptr<float>(), outputs[k].ptr<float>(), inputs[k].total());
    }
  }
};

}  // namespace

float fast_exp(float x) { return exp_approx(x); }

// The layer runs in place (in == out): without `ivdep` GCC's run-time alias check sends that case to
// its scalar copy of the loop, 4x slower. AVX2 gets its own clone (8 lanes, no FMA, so the same
// results as the SSE2 one), picked at load time.
__attribute__((target_clones("avx2", "default"))) void fast_sigmoid(const float* in, float* out,
                                                                    std::size_t n) {
#pragma GCC ivdep
  for (std::size_t i = 0; i < n; ++i) out[i] = 1.f / (1.f + exp_approx(-in[i]));
}

ScopedFastSigmoid::ScopedFastSigmoid() {
  cv::dnn::LayerFactory::registerLayer("Sigmoid", FastSigmoidLayer::create);
}

ScopedFastSigmoid::~ScopedFastSigmoid() { cv::dnn::LayerFactory::unregisterLayer("Sigmoid"); }

}  // namespace sp::dyn
