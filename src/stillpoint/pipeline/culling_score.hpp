#pragma once
// Scores dynamic-feature culling against ground-truth masks (dynsynth masks/<rgb stem>.png, 0 =
// static): a keypoint is truly dynamic when the mask is non-zero at its pixel.
#include <filesystem>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <vector>

namespace sp::pipeline {

class CullingScore {
 public:
  explicit CullingScore(std::filesystem::path masks_dir) : masks_dir_(std::move(masks_dir)) {}
  // `rgb_path` names the frame (its stem names the mask); frames without a mask are skipped.
  void add(const std::string& rgb_path, const std::vector<cv::KeyPoint>& keypoints,
           const std::vector<bool>& dropped);
  [[nodiscard]] nlohmann::json to_json() const;
  [[nodiscard]] double precision() const;
  [[nodiscard]] double recall() const;

 private:
  std::filesystem::path masks_dir_;
  std::size_t tp_ = 0, fp_ = 0, fn_ = 0, tn_ = 0, frames_ = 0;
};

}  // namespace sp::pipeline
