#pragma once
// Public place-descriptor API for loop closing. No libtorch here (pimpl), so including modules
// compile fast; link sp_place.
#include <Eigen/Core>
#include <filesystem>
#include <memory>
#include <opencv2/core.hpp>
#include <vector>

namespace sp::place {

class PlaceDescriptorExtractor {
 public:
  // Loads a ParC_NetVLAD model file (models/parc_netvlad/*.pt); throws sp::InputError when unreadable.
  // `threads` caps libtorch's intra-op threads (process-wide setting of libtorch).
  static PlaceDescriptorExtractor load(const std::filesystem::path& model_file, int threads = 1);

  PlaceDescriptorExtractor(PlaceDescriptorExtractor&&) noexcept;
  PlaceDescriptorExtractor& operator=(PlaceDescriptorExtractor&&) noexcept;
  ~PlaceDescriptorExtractor();

  // L2-normalised descriptor of an 8-bit BGR (or grey) image of any size; resized to the model's input.
  // Not thread-safe: use one extractor per thread.
  [[nodiscard]] Eigen::VectorXf describe(const cv::Mat& bgr);
  // Several images in one batch: row i is the descriptor of images[i].
  [[nodiscard]] Eigen::MatrixXf describe_batch(const std::vector<cv::Mat>& images);

  [[nodiscard]] int dimension() const;
  [[nodiscard]] int input_width() const;
  [[nodiscard]] int input_height() const;

 private:
  struct Impl;
  explicit PlaceDescriptorExtractor(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// Squared L2 distance between two descriptors (the retrieval metric; monotone in L2).
[[nodiscard]] inline float descriptor_distance_sq(const Eigen::VectorXf& a, const Eigen::VectorXf& b) {
  return (a - b).squaredNorm();
}

}  // namespace sp::place
