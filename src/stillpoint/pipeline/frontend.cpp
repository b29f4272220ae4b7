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

track::Frame FrontEnd::assemble(const io::FrameData& data, ExtractedFeatures features,
                                const std::vector<bool>& drop, const std::vector<bool>& suspect,
                                const std::vector<bool>& reserve) const {
  track::Frame frame;
  frame.index = data.index;
  frame.stamp = data.stamp;
  frame.extracted = features.keypoints.size();
  std::vector<cv::KeyPoint> raw;
  cv::Mat descriptors;
  raw.reserve(features.keypoints.size());
  std::vector<int> rows;
  for (std::size_t i = 0; i < features.keypoints.size(); ++i) {
    if (i < drop.size() && drop[i]) continue;
    raw.push_back(features.keypoints[i]);
    rows.push_back(static_cast<int>(i));
  }
  frame.culled = features.keypoints.size() - raw.size();
  if (!suspect.empty()) {
    frame.suspect.reserve(rows.size());
    for (int r : rows) frame.suspect.push_back(static_cast<std::size_t>(r) < suspect.size() && suspect[r]);
  }
  descriptors.create(static_cast<int>(rows.size()), 32, CV_8U);
  for (std::size_t r = 0; r < rows.size(); ++r) {
    features.descriptors.row(rows[r]).copyTo(descriptors.row(static_cast<int>(r)));
  }
  frame.features.keypoints = track::undistort_keypoints(raw, camera_);
  frame.features.descriptors = descriptors;
  track::attach_depth(frame.features, raw, data.depth, depth_);
  std::vector<cv::KeyPoint> raw_reserve;
  std::vector<int> reserve_rows;
  for (std::size_t i = 0; i < features.keypoints.size() && i < reserve.size(); ++i) {
    if (!reserve[i] || i >= drop.size() || !drop[i]) continue;
    raw_reserve.push_back(features.keypoints[i]);
    reserve_rows.push_back(static_cast<int>(i));
  }
  if (!reserve_rows.empty()) {
    cv::Mat reserve_desc(static_cast<int>(reserve_rows.size()), 32, CV_8U);
    for (std::size_t r = 0; r < reserve_rows.size(); ++r)
      features.descriptors.row(reserve_rows[r]).copyTo(reserve_desc.row(static_cast<int>(r)));
    frame.reserve.keypoints = track::undistort_keypoints(raw_reserve, camera_);
    frame.reserve.descriptors = reserve_desc;
    track::attach_depth(frame.reserve, raw_reserve, data.depth, depth_);
  }
  frame.gray = features.gray;
  cv::resize(data.bgr, frame.thumbnail, cv::Size(320, 240), 0, 0, cv::INTER_AREA);
  return frame;
}

}  // namespace sp::pipeline
