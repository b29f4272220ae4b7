#pragma once
// A YOLO detector on cv::dnn (ONNX or Darknet) for the moving-object candidates.
#include <opencv2/dnn.hpp>
#include <string>

#include "stillpoint/dynamic/decoders.hpp"
#include "stillpoint/dynamic/detection.hpp"

namespace sp::dyn {

class YoloDetector {
 public:
  // Loads the network; throws sp::Error naming the file when it cannot be loaded, and
  // sp::ConfigError for an unknown decoder or class name.
  explicit YoloDetector(const DetectorConfig& cfg);

  // Detects objects of the configured dynamic classes in a BGR (or gray) image. Not thread-safe
  // (one cv::dnn::Net); use one detector per thread or AsyncDetector.
  Detections detect(const cv::Mat& bgr);

  [[nodiscard]] const DetectorConfig& config() const noexcept { return cfg_; }
  [[nodiscard]] const std::string& decoder() const noexcept { return decoder_; }

 private:
  DetectorConfig cfg_;
  cv::dnn::Net net_;
  std::vector<std::string> out_names_;
  std::string decoder_;           // resolved after the first forward when "auto"
  std::vector<bool> keep_class_;  // class id -> reported
};

}  // namespace sp::dyn
