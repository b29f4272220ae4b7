#include "stillpoint/pipeline/culling_score.hpp"

#include <opencv2/imgcodecs.hpp>

namespace sp::pipeline {

void CullingScore::add(const std::string& rgb_path, const std::vector<cv::KeyPoint>& keypoints,
                       const std::vector<bool>& dropped) {
  const auto mask_file = masks_dir_ / (std::filesystem::path(rgb_path).stem().string() + ".png");
  if (!std::filesystem::exists(mask_file)) return;
  const cv::Mat mask = cv::imread(mask_file.string(), cv::IMREAD_UNCHANGED);
  if (mask.empty() || mask.type() != CV_8UC1) return;
  ++frames_;
  for (std::size_t i = 0; i < keypoints.size(); ++i) {
    const int u = std::clamp(static_cast<int>(keypoints[i].pt.x + 0.5f), 0, mask.cols - 1);
    const int v = std::clamp(static_cast<int>(keypoints[i].pt.y + 0.5f), 0, mask.rows - 1);
    const bool truth = mask.at<std::uint8_t>(v, u) != 0;
    const bool pred = i < dropped.size() && dropped[i];
    if (truth && pred) ++tp_;
    if (!truth && pred) ++fp_;
    if (truth && !pred) ++fn_;
    if (!truth && !pred) ++tn_;
  }
}

double CullingScore::precision() const {
  return tp_ + fp_ == 0 ? 1.0 : static_cast<double>(tp_) / static_cast<double>(tp_ + fp_);
}
double CullingScore::recall() const {
  return tp_ + fn_ == 0 ? 1.0 : static_cast<double>(tp_) / static_cast<double>(tp_ + fn_);
}

nlohmann::json CullingScore::to_json() const {
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
