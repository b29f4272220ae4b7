// Learns the decorrelated ORB sampling pattern (rBRIEF-style): from a pool of candidate tests drawn by
// OrbPattern::generate with seeds kDefaultSeed + k, keep 256 tests with the least bias and low
// mutual correlation on steered keypoint patches of the given frames. Prints a C++ table for
// OrbPattern::decorrelated() in orb_pattern.cpp.  Usage: learn_pattern <frames...>   (we used every 15th
// frame of both dynsynth/*_150 sequences in sorted order: see the comment in orb_pattern.cpp)
#include <spdlog/spdlog.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdio>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "stillpoint/features/orb_extractor.hpp"

using sp::feat::OrbConfig;
using sp::feat::OrbExtractor;
using sp::feat::OrbPattern;

int main(int argc, char** argv) {
  constexpr int kPools = 64;  // candidate patterns of 256 pairs each
  constexpr int kTests = kPools * OrbPattern::kPairs;
  std::vector<int> px, py;
  for (int k = 0; k < kPools; ++k) {
    const OrbPattern p = OrbPattern::generate(OrbPattern::kDefaultSeed + static_cast<std::uint64_t>(k));
    for (int i = 0; i < 2 * OrbPattern::kPairs; ++i) {
      px.push_back(p.x[static_cast<std::size_t>(i)]);
      py.push_back(p.y[static_cast<std::size_t>(i)]);
    }
  }
  // bits[t]: outcome of test t on every keypoint, packed 64 per word.
  std::vector<std::vector<std::uint64_t>> bits(kTests);
  OrbExtractor orb(OrbConfig{}, OrbPattern::generate());
  long n = 0;
  for (int a = 1; a < argc; ++a) {
    const cv::Mat img = cv::imread(argv[a], cv::IMREAD_GRAYSCALE);
    if (img.empty()) {
      spdlog::error("cannot read {}", argv[a]);
      return 1;
    }
    std::vector<cv::KeyPoint> kps;
    cv::Mat desc;
    orb.extract(img, kps, desc);
    std::vector<cv::Mat> blurred(static_cast<std::size_t>(orb.levels()));
    for (int l = 0; l < orb.levels(); ++l) {
      cv::GaussianBlur(orb.level_image(l), blurred[static_cast<std::size_t>(l)], cv::Size(7, 7), 2, 2,
                       cv::BORDER_REFLECT_101);
    }
    for (const cv::KeyPoint& k : kps) {
      const cv::Mat& b = blurred[static_cast<std::size_t>(k.octave)];
      const double s = orb.scale_factors()[static_cast<std::size_t>(k.octave)];
      const int x = cvRound(k.pt.x / s), y = cvRound(k.pt.y / s);
      if (x < 16 || y < 16 || x >= b.cols - 16 || y >= b.rows - 16) continue;
      const float ang = k.angle * static_cast<float>(CV_PI / 180.0);
      const float ca = std::cos(ang), sa = std::sin(ang);
      const auto at = [&](int i) {
        const float fx = static_cast<float>(px[static_cast<std::size_t>(i)]);
        const float fy = static_cast<float>(py[static_cast<std::size_t>(i)]);
        return b.at<std::uint8_t>(y + cvRound(fx * sa + fy * ca), x + cvRound(fx * ca - fy * sa));
      };
      if (n % 64 == 0) {
        for (auto& v : bits) v.push_back(0);
      }
      for (int t = 0; t < kTests; ++t) {
        if (at(2 * t) < at(2 * t + 1)) bits[static_cast<std::size_t>(t)].back() |= 1ULL << (n % 64);
      }
      ++n;
    }
  }
  if (n < 1000) {
    spdlog::error("too few keypoints ({})", n);
    return 1;
  }
  std::vector<double> mean(kTests);
  for (int t = 0; t < kTests; ++t) {
    long c = 0;
    for (std::uint64_t w : bits[static_cast<std::size_t>(t)]) c += std::popcount(w);
    mean[static_cast<std::size_t>(t)] = static_cast<double>(c) / static_cast<double>(n);
  }
  std::vector<int> order(kTests);
  for (int t = 0; t < kTests; ++t) order[static_cast<std::size_t>(t)] = t;
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return std::abs(mean[static_cast<std::size_t>(a)] - 0.5) <
           std::abs(mean[static_cast<std::size_t>(b)] - 0.5);
  });
  // Greedy: least biased first, skipping tests correlated with a chosen one; relax until 256.
  std::vector<int> chosen;
  for (double limit = 0.2; chosen.size() < OrbPattern::kPairs; limit += 0.02) {
    chosen.clear();
    for (int t : order) {
      const double pa = mean[static_cast<std::size_t>(t)];
      bool ok = true;
      for (int u : chosen) {
        long c = 0;
        const auto& bt = bits[static_cast<std::size_t>(t)];
        const auto& bu = bits[static_cast<std::size_t>(u)];
        for (std::size_t w = 0; w < bt.size(); ++w) c += std::popcount(bt[w] & bu[w]);
        const double pb = mean[static_cast<std::size_t>(u)],
                     pab = static_cast<double>(c) / static_cast<double>(n);
        const double corr = (pab - pa * pb) / std::sqrt(pa * (1 - pa) * pb * (1 - pb) + 1e-12);
        if (std::abs(corr) > limit) {
          ok = false;
          break;
        }
      }
      if (ok) chosen.push_back(t);
      if (chosen.size() == OrbPattern::kPairs) break;
    }
    spdlog::info("correlation limit {:.2f}: {} tests", limit, chosen.size());
  }
  spdlog::info("{} keypoints", n);
  for (std::size_t i = 0; i < chosen.size(); ++i) {
    const int t = chosen[i];
    std::printf("{%d, %d, %d, %d},%s", px[static_cast<std::size_t>(2 * t)],
                py[static_cast<std::size_t>(2 * t)], px[static_cast<std::size_t>(2 * t + 1)],
                py[static_cast<std::size_t>(2 * t + 1)], i % 6 == 5 ? "\n" : " ");
  }
  std::printf("\n");
  return 0;
}
