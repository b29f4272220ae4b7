#pragma once
// A keyframe makes map points straight from depth; a point on something moving that culling let
// through (a person entering at the image border, never boxed) then drags the following frames' poses
// with it. Before a point is made, this check follows its pixel back to the previous frame by optical
// flow and asks whether it moved as the tracked camera motion says a static point would. Its own LK,
// not the culling's: that flow covers a bucketed subset of the keypoints and is absent with culling off,
// and this one runs on keyframes only.
#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <vector>

#include "stillpoint/common/config_reader.hpp"
#include "stillpoint/geometry/camera.hpp"
#include "stillpoint/geometry/lie.hpp"

namespace sp::track {

struct NewPointMotionCheckConfig {
  // px: a candidate whose flow lands farther than this from where the tracked poses put it is not made
  // a point. 0: off (every candidate is made, ORB-SLAM's rule). 3 passed the fresh-room rule of session
  // 30 (docs/dynamic.md "New points must move as the camera did").
  double max_residual_px = 3.0;
  double fb_max_px = 0.5;  // forward-backward flow error above which the flow is unknown (point kept)
  int lk_window = 9;
  int lk_levels = 3;
  static NewPointMotionCheckConfig from_yaml(const ConfigReader& r);
  [[nodiscard]] bool enabled() const { return max_residual_px > 0; }
};

class NewPointMotionCheck {
 public:
  NewPointMotionCheck(const NewPointMotionCheckConfig& config, const geo::CameraIntrinsics& camera);

  // Per candidate (ideal pixel in the current frame, its depth): false when it moved unlike a static
  // point under T_prev_cur (current camera frame -> previous camera frame); true when it agrees or
  // when its flow is unknown. The images are the raw (distorted) grey frames.
  [[nodiscard]] std::vector<bool> static_candidates(const cv::Mat& prev_gray, const cv::Mat& cur_gray,
                                                    const geo::SE3& T_prev_cur,
                                                    const std::vector<Eigen::Vector2d>& ideal_px,
                                                    const std::vector<double>& depth) const;

  [[nodiscard]] const NewPointMotionCheckConfig& config() const { return config_; }

 private:
  NewPointMotionCheckConfig config_;
  geo::CameraIntrinsics camera_;
};

}  // namespace sp::track
