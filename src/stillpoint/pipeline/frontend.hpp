#pragma once
// Turns a decoded RGB-D frame into features: grey image, ORB, undistortion, depth per feature.
// Dynamic culling sits between extract() and assemble(), so moving features never reach tracking.
#include <vector>

#include "stillpoint/features/orb_extractor.hpp"
#include "stillpoint/io/frame.hpp"
#include "stillpoint/tracking/frame.hpp"

namespace sp::pipeline {

struct ExtractedFeatures {
  cv::Mat gray;
  std::vector<cv::KeyPoint> keypoints;  // raw (distorted) image coordinates
  cv::Mat descriptors;
};

class FrontEnd {
 public:
  FrontEnd(const feat::OrbConfig& orb, const geo::CameraIntrinsics& camera, const track::DepthModel& depth);

  ExtractedFeatures extract(const io::FrameData& data);
  // Where culling removed many features, the ORB budget was spent on moving objects. Detects again on
  // the same pyramid, away from dynamic boxes, removed features and kept ones, and appends what it finds
  // (flagged keep / not suspect in `drop` / `suspect`). Returns how many were added.
  std::size_t refill(ExtractedFeatures& features, std::vector<bool>& drop, std::vector<bool>& suspect,
                     const std::vector<cv::Rect2f>& dynamic_boxes,
                     const feat::OrbExtractor::AgainOptions& options = {});
  // Builds the tracker's frame; features flagged in `drop` (dynamic) are removed, those flagged in
  // `suspect` (kept, but near a detected object) are marked for the tracker's pose guard. Dropped
  // features flagged in `reserve` (on a person proven still) go to the frame's reserve set.
  track::Frame assemble(const io::FrameData& data, ExtractedFeatures features, const std::vector<bool>& drop,
                        const std::vector<bool>& suspect = {}, const std::vector<bool>& reserve = {}) const;
  [[nodiscard]] map::ScalePyramid pyramid() const;

 private:
  // The features at `rows`: positions undistorted, descriptors copied, depth looked up.
  [[nodiscard]] map::FeatureSet subset(const ExtractedFeatures& features, const std::vector<int>& rows,
                                       const cv::Mat& depth) const;
  feat::OrbExtractor extractor_;
  geo::CameraIntrinsics camera_;
  track::DepthModel depth_;
};

}  // namespace sp::pipeline
