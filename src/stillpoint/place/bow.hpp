#pragma once
// Baseline for the ablation: a flat binary vocabulary of ORB words (k-majority k-means under Hamming
// distance), TF-IDF weighting and the L1 score of DBoW2. Only used by `stillpoint vpr` (the
// project's loop-closing vocabulary lives in sp::loop).
#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <opencv2/core.hpp>
#include <vector>

namespace sp::place {

class BowVocabulary {
 public:
  // `per_image` holds one CV_8U N×32 ORB descriptor matrix per training image.
  static BowVocabulary train(const std::vector<cv::Mat>& per_image, int words, int iterations,
                             std::uint64_t seed);
  static BowVocabulary load(const std::filesystem::path& file);
  void save(const std::filesystem::path& file) const;

  // L1-normalised TF-IDF vector of one image's descriptors.
  [[nodiscard]] Eigen::VectorXf transform(const cv::Mat& descriptors) const;
  // DBoW2's L1 score in [0, 1]: 1 − ½‖a − b‖₁ of L1-normalised vectors (1 = identical).
  [[nodiscard]] static float score(const Eigen::VectorXf& a, const Eigen::VectorXf& b);
  [[nodiscard]] int size() const { return words_.rows; }
  [[nodiscard]] int word_of(const cv::Mat& descriptor_row) const;

 private:
  cv::Mat words_;           // K×32 CV_8U
  std::vector<float> idf_;  // log(N / n_i)
};

// ORB descriptors of an image (grey or BGR); images smaller than 240 px on their short side are
// upscaled first so that ORB's border margin leaves room for keypoints.
cv::Mat orb_descriptors(const cv::Mat& image, int features = 500);

}  // namespace sp::place
