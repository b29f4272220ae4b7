#pragma once
// A tracker Frame made of a synthetic scene's exact projections (synthetic_map.hpp's observe()),
// stamped at 30 Hz: the input of the tracker tests.
#include "stillpoint/tracking/frame.hpp"
#include "synthetic_map.hpp"

namespace sp::testing {

inline track::Frame synthetic_frame(const SyntheticScene& scene, const geo::SE3& T_cw, std::size_t index,
                                    const geo::CameraIntrinsics& cam, double bf) {
  track::Frame f;
  f.index = index;
  f.stamp = static_cast<double>(index) / 30.0;
  f.features = observe(scene, T_cw, cam, bf).features;
  f.extracted = f.features.size();
  return f;
}

// A frame with no features at all (the lens covered), stamped like synthetic_frame.
inline track::Frame blank_frame(std::size_t index) {
  track::Frame f;
  f.index = index;
  f.stamp = static_cast<double>(index) / 30.0;
  f.features.descriptors = cv::Mat(0, 32, CV_8U);
  return f;
}

}  // namespace sp::testing
