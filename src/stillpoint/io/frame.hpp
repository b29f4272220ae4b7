#pragma once
// One associated RGB-D frame as it leaves the reader.
#include <cstddef>
#include <opencv2/core.hpp>
#include <string>

namespace sp::io {

struct FrameData {
  std::size_t index = 0;  // position in the sequence's association list (gaps where frames were skipped)
  double stamp = 0;       // colour timestamp, seconds
  double depth_stamp = 0;
  cv::Mat bgr;           // CV_8UC3
  cv::Mat depth;         // CV_32FC1 metres, 0 = invalid (no reading or outside [depth_min, depth_max])
  std::string rgb_path;  // path of the colour image (sequence folder joined with the listed path)
};

}  // namespace sp::io
