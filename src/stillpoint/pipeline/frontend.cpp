#include "stillpoint/pipeline/frontend.hpp"

#include <algorithm>
#include <opencv2/imgproc.hpp>

namespace sp::pipeline {

FrontEnd::FrontEnd(const feat::OrbConfig& orb, const geo::CameraIntrinsics& camera,
                   const track::DepthModel& depth)
    : extractor_(orb), camera_(camera), depth_(depth) {}

map::ScalePyramid FrontEnd::pyramid() const {
  return map::ScalePyramid::make(extractor_.levels(), extractor_.scale_factor());
}

ExtractedFeatures FrontEnd::extract(const io::FrameData& data) {
  ExtractedFeatures out;
  if (data.bgr.channels() == 3) {
    cv::cvtColor(data.bgr, out.gray, cv::COLOR_BGR2GRAY);
  } else {
    out.gray = data.bgr;
  }
  extractor_.extract(out.gray, out.keypoints, out.descriptors);
  return out;
}

std::size_t FrontEnd::refill(ExtractedFeatures& features, std::vector<bool>& drop, std::vector<bool>& suspect,
                             const std::vector<cv::Rect2f>& dynamic_boxes,
                             const feat::OrbExtractor::AgainOptions& options) {
  cv::Mat mask(features.gray.size(), CV_8UC1, cv::Scalar(255));
  for (const cv::Rect2f& b : dynamic_boxes) {
    cv::rectangle(
        mask,
        cv::Rect(cv::Point(static_cast<int>(b.x) - 4, static_cast<int>(b.y) - 4),
                 cv::Point(static_cast<int>(b.x + b.width) + 4, static_cast<int>(b.y + b.height) + 4)),
        cv::Scalar(0), cv::FILLED);
  }
  // Removed features (a moving cluster outside any box) block a wider disc than kept ones, which
  // only must not be detected twice.
  for (std::size_t i = 0; i < features.keypoints.size(); ++i) {
    const bool removed = i < drop.size() && drop[i];
    const double scale = extractor_.scale_factors()[static_cast<std::size_t>(
        std::clamp(features.keypoints[i].octave, 0, extractor_.levels() - 1))];
    cv::circle(mask, features.keypoints[i].pt, static_cast<int>(std::lround((removed ? 12.0 : 3.0) * scale)),
               cv::Scalar(0), cv::FILLED);
  }
  std::vector<cv::KeyPoint> extra;
  cv::Mat extra_desc;
  extractor_.extract_again(mask, extra, extra_desc, options);
  if (extra.empty()) return 0;
  features.keypoints.insert(features.keypoints.end(), extra.begin(), extra.end());
  cv::vconcat(features.descriptors, extra_desc, features.descriptors);
  drop.resize(features.keypoints.size(), false);
  if (!suspect.empty()) suspect.resize(features.keypoints.size(), false);
  return extra.size();
}

map::FeatureSet FrontEnd::subset(const ExtractedFeatures& features, const std::vector<int>& rows,
                                 const cv::Mat& depth) const {
  map::FeatureSet out;
  std::vector<cv::KeyPoint> raw;
  raw.reserve(rows.size());
  cv::Mat descriptors(static_cast<int>(rows.size()), 32, CV_8U);
  for (std::size_t r = 0; r < rows.size(); ++r) {
    raw.push_back(features.keypoints[static_cast<std::size_t>(rows[r])]);
    features.descriptors.row(rows[r]).copyTo(descriptors.row(static_cast<int>(r)));
  }
  out.keypoints = track::undistort_keypoints(raw, camera_);
  out.descriptors = descriptors;
  track::attach_depth(out, raw, depth, depth_);
  return out;
}

track::Frame FrontEnd::assemble(const io::FrameData& data, ExtractedFeatures features,
                                const std::vector<bool>& drop, const std::vector<bool>& suspect,
                                const std::vector<bool>& reserve) const {
  track::Frame frame;
  frame.index = data.index;
  frame.stamp = data.stamp;
  frame.extracted = features.keypoints.size();
  std::vector<int> rows, reserve_rows;
  rows.reserve(features.keypoints.size());
  for (std::size_t i = 0; i < features.keypoints.size(); ++i) {
    if (i >= drop.size() || !drop[i]) {
      rows.push_back(static_cast<int>(i));
    } else if (i < reserve.size() && reserve[i]) {
      reserve_rows.push_back(static_cast<int>(i));
    }
  }
  frame.culled = features.keypoints.size() - rows.size();
  if (!suspect.empty()) {
    frame.suspect.reserve(rows.size());
    for (int r : rows) frame.suspect.push_back(static_cast<std::size_t>(r) < suspect.size() && suspect[r]);
  }
  frame.features = subset(features, rows, data.depth);
  if (!reserve_rows.empty()) frame.reserve = subset(features, reserve_rows, data.depth);
  frame.gray = features.gray;
  cv::resize(data.bgr, frame.thumbnail, cv::Size(320, 240), 0, 0, cv::INTER_AREA);
  return frame;
}

}  // namespace sp::pipeline
