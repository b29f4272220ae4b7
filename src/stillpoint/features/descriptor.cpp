#include "stillpoint/features/descriptor.hpp"

#include "stillpoint/common/error.hpp"

namespace sp::feat {

int hamming_distance(const cv::Mat& a_row, const cv::Mat& b_row) {
  const auto ok = [](const cv::Mat& m) {
    return m.type() == CV_8UC1 && m.rows == 1 && m.cols == kDescriptorBytes;
  };
  if (!ok(a_row) || !ok(b_row)) throw sp::Error("hamming_distance: descriptors must be 1 x 32 CV_8U rows");
  return hamming_distance(a_row.ptr<std::uint8_t>(), b_row.ptr<std::uint8_t>());
}

}  // namespace sp::feat
