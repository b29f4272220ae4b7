#include "stillpoint/place/bow.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <fstream>
#include <numeric>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>
#include <random>

#include "stillpoint/common/error.hpp"
#include "stillpoint/features/descriptor.hpp"

namespace sp::place {

namespace {

constexpr int kBytes = feat::kDescriptorBytes;

int nearest(const cv::Mat& words, const std::uint8_t* d) {
  int best = 0, best_d = 1 << 30;
  for (int k = 0; k < words.rows; ++k) {
    const int h = feat::hamming_distance(words.ptr<std::uint8_t>(k), d);
    if (h < best_d) best_d = h, best = k;
  }
  return best;
}

}  // namespace

cv::Mat orb_descriptors(const cv::Mat& image, int features) {
  cv::Mat grey;
  if (image.channels() == 3) {
    cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  } else {
    grey = image;
  }
  const int short_side = std::min(grey.rows, grey.cols);
  if (short_side < 240) {
    const double s = 240.0 / short_side;
    cv::resize(grey, grey, cv::Size(), s, s, cv::INTER_LINEAR);
  }
  auto orb = cv::ORB::create(features);
  std::vector<cv::KeyPoint> kps;
  cv::Mat desc;
  orb->detectAndCompute(grey, cv::noArray(), kps, desc);
  return desc;
}

BowVocabulary BowVocabulary::train(const std::vector<cv::Mat>& per_image, int words, int iterations,
                                   std::uint64_t seed) {
  cv::Mat all;
  for (const auto& d : per_image) {
    if (!d.empty()) all.push_back(d);
  }
  if (all.rows < words) throw sp::Error("BoW: fewer descriptors than words");
  std::mt19937_64 rng(seed);
  std::vector<int> idx(static_cast<size_t>(all.rows));
  std::iota(idx.begin(), idx.end(), 0);
  std::shuffle(idx.begin(), idx.end(), rng);
  BowVocabulary v;
  v.words_ = cv::Mat(words, kBytes, CV_8U);
  for (int k = 0; k < words; ++k) all.row(idx[static_cast<size_t>(k)]).copyTo(v.words_.row(k));
  std::vector<int> assign(static_cast<size_t>(all.rows));
  for (int it = 0; it < iterations; ++it) {
    for (int i = 0; i < all.rows; ++i)
      assign[static_cast<size_t>(i)] = nearest(v.words_, all.ptr<std::uint8_t>(i));
    // Majority vote per bit: the binary analogue of the mean.
    std::vector<std::vector<int>> ones(static_cast<size_t>(words), std::vector<int>(kBytes * 8, 0));
    std::vector<int> count(static_cast<size_t>(words), 0);
    for (int i = 0; i < all.rows; ++i) {
      const int k = assign[static_cast<size_t>(i)];
      ++count[static_cast<size_t>(k)];
      const auto* p = all.ptr<std::uint8_t>(i);
      for (int b = 0; b < kBytes * 8; ++b)
        ones[static_cast<size_t>(k)][static_cast<size_t>(b)] += (p[b / 8] >> (b % 8)) & 1;
    }
    for (int k = 0; k < words; ++k) {
      if (count[static_cast<size_t>(k)] == 0) continue;  // keep an empty word where it is
      auto* w = v.words_.ptr<std::uint8_t>(k);
      std::fill(w, w + kBytes, 0);
      for (int b = 0; b < kBytes * 8; ++b) {
        if (2 * ones[static_cast<size_t>(k)][static_cast<size_t>(b)] > count[static_cast<size_t>(k)]) {
          w[b / 8] |= static_cast<std::uint8_t>(1u << (b % 8));
        }
      }
    }
  }
  // IDF over training images.
  std::vector<int> df(static_cast<size_t>(words), 0);
  int n_images = 0;
  for (const auto& d : per_image) {
    if (d.empty()) continue;
    ++n_images;
    std::vector<char> seen(static_cast<size_t>(words), 0);
    for (int i = 0; i < d.rows; ++i) seen[static_cast<size_t>(nearest(v.words_, d.ptr<std::uint8_t>(i)))] = 1;
    for (int k = 0; k < words; ++k) df[static_cast<size_t>(k)] += seen[static_cast<size_t>(k)];
  }
  v.idf_.resize(static_cast<size_t>(words));
  for (int k = 0; k < words; ++k) {
    v.idf_[static_cast<size_t>(k)] =
        std::log(static_cast<float>(n_images) / static_cast<float>(std::max(1, df[static_cast<size_t>(k)])));
  }
  return v;
}

int BowVocabulary::word_of(const cv::Mat& row) const { return nearest(words_, row.ptr<std::uint8_t>(0)); }

Eigen::VectorXf BowVocabulary::transform(const cv::Mat& d) const {
  Eigen::VectorXf v = Eigen::VectorXf::Zero(size());
  for (int i = 0; i < d.rows; ++i) v[nearest(words_, d.ptr<std::uint8_t>(i))] += 1.0f;
  for (int k = 0; k < size(); ++k) v[k] *= idf_[static_cast<size_t>(k)];
  const float s = v.lpNorm<1>();
  if (s > 0) v /= s;
  return v;
}

float BowVocabulary::score(const Eigen::VectorXf& a, const Eigen::VectorXf& b) {
  // An image without features matches nothing (as in DBoW2); without this it would score 0.5 against
  // everything and outrank real matches, whose vectors overlap only partly.
  if (a.isZero() || b.isZero()) return 0.0f;
  return 1.0f - 0.5f * (a - b).lpNorm<1>();
}

void BowVocabulary::save(const std::filesystem::path& file) const {
  std::ofstream out(file, std::ios::binary);
  if (!out) throw sp::Error("cannot write " + file.string());
  const std::int32_t k = size();
  out.write("SPBOW1\n", 7);
  out.write(reinterpret_cast<const char*>(&k), sizeof k);
  out.write(reinterpret_cast<const char*>(words_.data), static_cast<std::streamsize>(k) * kBytes);
  out.write(reinterpret_cast<const char*>(idf_.data()), static_cast<std::streamsize>(k) * 4);
}

BowVocabulary BowVocabulary::load(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw sp::InputError(file.string(), 0, "cannot open vocabulary");
  char magic[7];
  std::int32_t k = 0;
  in.read(magic, 7);
  in.read(reinterpret_cast<char*>(&k), sizeof k);
  if (!in || std::string(magic, 7) != "SPBOW1\n" || k <= 0 || k > 1000000) {
    throw sp::InputError(file.string(), 0, "not a StillPoint place BoW vocabulary");
  }
  BowVocabulary v;
  v.words_ = cv::Mat(k, kBytes, CV_8U);
  v.idf_.resize(static_cast<size_t>(k));
  in.read(reinterpret_cast<char*>(v.words_.data), static_cast<std::streamsize>(k) * kBytes);
  in.read(reinterpret_cast<char*>(v.idf_.data()), static_cast<std::streamsize>(k) * 4);
  if (!in) throw sp::InputError(file.string(), 0, "truncated vocabulary");
  return v;
}

}  // namespace sp::place
