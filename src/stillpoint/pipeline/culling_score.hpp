#pragma once
// Scores dynamic-feature culling against ground-truth masks (dynsynth masks/<rgb stem>.png, 0 =
// static): a keypoint is truly dynamic when the mask is non-zero at its pixel.
//
// Scoring is evaluation, not SLAM: add() only keeps the frame's keypoint pixels (4 bytes each) and
// the masks are read when the score is first asked for, after the run, so the tracking thread does
// not decode a mask image per frame.
#include <cstdint>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace sp::pipeline {

class CullingScore {
 public:
  explicit CullingScore(std::filesystem::path masks_dir) : masks_dir_(std::move(masks_dir)) {}
  // `rgb_path` names the frame (its stem names the mask); frames without a mask are skipped.
  void add(const std::string& rgb_path, const std::vector<cv::KeyPoint>& keypoints,
           const std::vector<bool>& dropped);
  // The first of these reads the masks of every frame added so far.
  [[nodiscard]] nlohmann::json to_json() const;
  [[nodiscard]] double precision() const;
  [[nodiscard]] double recall() const;

 private:
  struct Pixel {
    std::uint16_t u, v;
  };
  struct PendingFrame {
    std::string mask_stem;
    std::vector<Pixel> pixels;
    std::vector<bool> dropped;
  };
  void score_pending() const;  // reads the pending frames' masks and adds them to the counts

  std::filesystem::path masks_dir_;
  // Filled lazily by the const accessors (single-threaded use: the tracking thread, then the writer).
  mutable std::vector<PendingFrame> pending_;
  mutable std::size_t tp_ = 0, fp_ = 0, fn_ = 0, tn_ = 0, frames_ = 0;
};

}  // namespace sp::pipeline
