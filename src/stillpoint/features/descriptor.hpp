#pragma once
// Hamming distance between 256-bit ORB descriptors (32 bytes).
#include <bit>
#include <cstdint>
#include <cstring>
#include <opencv2/core/mat.hpp>
#include <vector>

namespace sp::feat {

constexpr int kDescriptorBytes = 32;

// Distance between two 32-byte descriptors: popcount over four 64-bit words.
inline int hamming_distance(const std::uint8_t* a, const std::uint8_t* b) {
  int d = 0;
  for (int i = 0; i < kDescriptorBytes; i += 8) {
    std::uint64_t wa = 0, wb = 0;
    std::memcpy(&wa, a + i, 8);  // memcpy: rows need not be 8-byte aligned
    std::memcpy(&wb, b + i, 8);
    d += std::popcount(wa ^ wb);
  }
  return d;
}

// The descriptor with the least median distance to the others (ORB-SLAM's representative
// descriptor of a map point seen in several keyframes); -1 when `descs` is empty.
int distinctive_descriptor_index(const std::vector<const std::uint8_t*>& descs);

// Rows of descriptor matrices (1 x 32, CV_8U). Throws sp::Error on another shape or type.
int hamming_distance(const cv::Mat& a_row, const cv::Mat& b_row);

}  // namespace sp::feat
