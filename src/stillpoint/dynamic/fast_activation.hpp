#pragma once
// A vectorisable logistic sigmoid for the detector's cv::dnn network. YOLOX's SiLU activations
// (x * sigmoid(x)) spend a third of a YOLOX-nano forward pass in OpenCV 4.6's Sigmoid layer, which
// calls scalar expf per element; this one evaluates exp by range reduction and a minimax polynomial
// in plain float arithmetic that the compiler turns into SIMD (SSE2 / NEON), relative error < 2e-7.
#include <cstddef>

namespace sp::dyn {

// out[i] = 1 / (1 + exp(-in[i])); in and out may be the same array.
void fast_sigmoid(const float* in, float* out, std::size_t n);

// exp(x) with x clamped to [-87, 87] (the float range): relative error < 2e-7.
float fast_exp(float x);

// While alive, cv::dnn networks read from files get fast_sigmoid for their "Sigmoid" layers (the
// layer type is registered with OpenCV's layer factory and withdrawn again on destruction). Keep it
// around the readNet* call only. OpenCV's layer factory is process-wide: networks loaded on other
// threads meanwhile get the fast layer too (same results, so harmless).
class ScopedFastSigmoid {
 public:
  ScopedFastSigmoid();
  ~ScopedFastSigmoid();
  ScopedFastSigmoid(const ScopedFastSigmoid&) = delete;
  ScopedFastSigmoid& operator=(const ScopedFastSigmoid&) = delete;
};

}  // namespace sp::dyn
