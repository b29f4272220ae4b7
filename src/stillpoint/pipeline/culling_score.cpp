#include "stillpoint/pipeline/culling_score.hpp"

#include <algorithm>
#include <cmath>
#include <opencv2/imgcodecs.hpp>

namespace sp::pipeline {

void CullingScore::add(const std::string& rgb_path, const std::vector<cv::KeyPoint>& keypoints,
                       const std::vector<bool>& dropped) {
  PendingFrame f;
  f.mask_stem = std::filesystem::path(rgb_path).stem().string();
  f.pixels.reserve(keypoints.size());
  f.dropped.reserve(keypoints.size());
  for (std::size_t i = 0; i < keypoints.size(); ++i) {
    // Nearest pixel; negative positions clamp to 0 here, the far border when the mask is read.
    const auto u = static_cast<long>(std::lround(std::max(0.f, keypoints[i].pt.x)));
    const auto v = static_cast<long>(std::lround(std::max(0.f, keypoints[i].pt.y)));
    f.pixels.push_back(
        {static_cast<std::uint16_t>(std::min(u, 65535L)), static_cast<std::uint16_t>(std::min(v, 65535L))});
    f.dropped.push_back(i < dropped.size() && dropped[i]);
  }
  pending_.push_back(std::move(f));
}

void CullingScore::score_pending() const {
  for (const PendingFrame& f : pending_) {
    const auto mask_file = masks_dir_ / (f.mask_stem + ".png");
    if (!std::filesystem::exists(mask_file)) continue;
    const cv::Mat mask = cv::imread(mask_file.string(), cv::IMREAD_UNCHANGED);
    if (mask.empty() || mask.type() != CV_8UC1) continue;
    ++frames_;
    for (std::size_t i = 0; i < f.pixels.size(); ++i) {
      const int u = std::min(static_cast<int>(f.pixels[i].u), mask.cols - 1);
      const int v = std::min(static_cast<int>(f.pixels[i].v), mask.rows - 1);
      const bool truth = mask.at<std::uint8_t>(v, u) != 0;
      const bool pred = f.dropped[i];
      if (truth && pred) ++tp_;
      if (!truth && pred) ++fp_;
      if (truth && !pred) ++fn_;
      if (!truth && !pred) ++tn_;
    }
  }
  pending_.clear();
}

double CullingScore::precision() const {
  score_pending();
  return tp_ + fp_ == 0 ? 1.0 : static_cast<double>(tp_) / static_cast<double>(tp_ + fp_);
}
double CullingScore::recall() const {
  score_pending();
  return tp_ + fn_ == 0 ? 1.0 : static_cast<double>(tp_) / static_cast<double>(tp_ + fn_);
}

nlohmann::json CullingScore::to_json() const {
  score_pending();
  return {{"frames", frames_},
          {"true_dynamic_keypoints", tp_ + fn_},
          {"culled_keypoints", tp_ + fp_},
          {"precision", precision()},
          {"recall", recall()},
          {"tp", tp_},
          {"fp", fp_},
          {"fn", fn_},
          {"tn", tn_}};
}

}  // namespace sp::pipeline
