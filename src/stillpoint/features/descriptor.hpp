#pragma once
// Hamming distance between 256-bit ORB descriptors (32 bytes).
#include <bit>
#include <cstdint>
#include <cstring>
#include <opencv2/core/mat.hpp>
#include <vector>

namespace sp::feat {

constexpr int kDescriptorBytes = 32;

// Distance between two 32-byte descriptors: popcount over four 64-bit words. Where the target has a
// popcount instruction (x86-64 built with it, AArch64) std::popcount is one; the plain x86-64
// baseline would call libgcc's __popcountdi2 per word (0.7 % of a whole run in `perf`), so there the
// bits are counted in registers: per-byte counts of the four words summed, then the bytes added up.
inline int hamming_distance(const std::uint8_t* a, const std::uint8_t* b) {
#if defined(__POPCNT__) || defined(__aarch64__) || !(defined(__x86_64__) || defined(__i386__))
  int d = 0;
  for (int i = 0; i < kDescriptorBytes; i += 8) {
    std::uint64_t wa = 0, wb = 0;
    std::memcpy(&wa, a + i, 8);  // memcpy: rows need not be 8-byte aligned
    std::memcpy(&wb, b + i, 8);
    d += std::popcount(wa ^ wb);
  }
  return d;
#else
  std::uint64_t bytes = 0;  // per-byte bit counts, at most 4 x 8 = 32 per byte
  for (int i = 0; i < kDescriptorBytes; i += 8) {
    std::uint64_t wa = 0, wb = 0;
    std::memcpy(&wa, a + i, 8);
    std::memcpy(&wb, b + i, 8);
    std::uint64_t x = wa ^ wb;
    x -= (x >> 1) & 0x5555555555555555ULL;
    x = (x & 0x3333333333333333ULL) + ((x >> 2) & 0x3333333333333333ULL);
    bytes += (x + (x >> 4)) & 0x0f0f0f0f0f0f0f0fULL;
  }
  // Bytes into 16-bit lanes (up to 64 each), then the four lanes into the top one (up to 256).
  const std::uint64_t lanes = (bytes & 0x00ff00ff00ff00ffULL) + ((bytes >> 8) & 0x00ff00ff00ff00ffULL);
  return static_cast<int>((lanes * 0x0001000100010001ULL) >> 48);
#endif
}

// The descriptor with the least median distance to the others (ORB-SLAM's representative
// descriptor of a map point seen in several keyframes); -1 when `descs` is empty.
int distinctive_descriptor_index(const std::vector<const std::uint8_t*>& descs);

// Rows of descriptor matrices (1 x 32, CV_8U). Throws sp::Error on another shape or type.
int hamming_distance(const cv::Mat& a_row, const cv::Mat& b_row);

}  // namespace sp::feat
