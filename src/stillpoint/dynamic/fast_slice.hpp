#pragma once
// A strided-copy Slice layer for the detector's cv::dnn network. YOLOX's input "Focus" block slices the
// image into four pixel phases (x[..., ::2, ::2] and its shifts): eight Slice layers with step 2 that
// take ~5 ms of a ~28 ms YOLOX-nano forward in OpenCV 4.6's generic Slice layer; as row copies they
// take well under 1 ms. Shapes come from OpenCV's own layer (so both agree on every range rule); only
// the copy is ours. Slices it does not cover (negative steps, splits by slice_point / num_split, more
// than one output) get OpenCV's layer unchanged.
#include <opencv2/core.hpp>
#include <opencv2/dnn.hpp>
#include <vector>

namespace sp::dyn {

// dst = src[start_0 :: step_0, start_1 :: step_1, ...] for dst's shape; float tensors of equal rank,
// start / step per axis (missing trailing axes: start 0, step 1).
void strided_slice(const cv::Mat& src, const std::vector<int>& start, const std::vector<int>& step,
                   cv::Mat& dst);

// Whether a network's layer is the strided-copy one (tests and diagnostics).
bool is_fast_slice(const cv::Ptr<cv::dnn::Layer>& layer);

// While alive, cv::dnn networks read from files get the strided-copy layer for their "Slice" layers
// (registered with OpenCV's layer factory, withdrawn on destruction); keep it around readNet* only.
// The factory is process-wide: networks loaded on other threads meanwhile get it too (same results).
class ScopedFastSlice {
 public:
  ScopedFastSlice();
  ~ScopedFastSlice();
  ScopedFastSlice(const ScopedFastSlice&) = delete;
  ScopedFastSlice& operator=(const ScopedFastSlice&) = delete;
};

}  // namespace sp::dyn
