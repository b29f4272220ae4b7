#include "stillpoint/pipeline/frontend.hpp"

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

track::Frame FrontEnd::assemble(const io::FrameData& data, ExtractedFeatures features,
                                const std::vector<bool>& drop, const std::vector<bool>& suspect) const {
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
  frame.gray = features.gray;
  cv::resize(data.bgr, frame.thumbnail, cv::Size(320, 240), 0, 0, cv::INTER_AREA);
  return frame;
}

}  // namespace sp::pipeline
