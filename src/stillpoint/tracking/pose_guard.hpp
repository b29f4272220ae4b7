#pragma once
// The pose guard's rules, apart from the tracker so they can be tested alone: a frame whose solved
// pose jumps against the constant-velocity prediction, while some of its inliers lie in or near
// detected objects, is re-solved without those; the re-solve is kept when it has enough inliers and
// lands closer to the prediction. A frame that jumped becomes no keyframe unless tracking is running
// out of points without one.
#include "stillpoint/common/config_reader.hpp"
#include "stillpoint/geometry/lie.hpp"

namespace sp::track {

struct PoseGuardConfig {
  bool enabled = true;
  double max_translation_m = 0.01;  // camera-centre deviation from the prediction that is a jump [0.001, 1]
  double max_rotation_deg = 1.0;    // rotation deviation from the prediction that is a jump [0.05, 45]
  double min_suspect_share = 0.02;  // share of inliers near objects needed to blame them [0, 1]
  // A jumped frame still becomes a keyframe (when the policy asks for one) once its inliers fall below
  // this share of the reference keyframe's tracked points (ORB-SLAM's "weak tracking" ratio): a
  // possibly disturbed keyframe costs less than losing the track. Vetoing every jump starved the map
  // while a person filled half the view during a fast turn (tracking lost). 0: every jump vetoes. [0, 1]
  double keyframe_below_reference_share = 0.25;
  static PoseGuardConfig from_yaml(const ConfigReader& r);
};

struct PoseGuardStats {
  std::size_t jumps = 0;                   // frames that jumped with suspect inliers
  std::size_t resolved = 0;                // ... whose pose was replaced by the solve without them
  std::size_t keyframes_vetoed = 0;        // keyframes not made because the frame jumped
  std::size_t keyframes_despite_jump = 0;  // keyframes made from a jumped frame, tracking running out
};

struct PoseDeviation {
  double translation_m = 0;  // distance between the camera centres
  double rotation_deg = 0;   // angle of the relative rotation
  [[nodiscard]] bool within(double max_translation_m, double max_rotation_deg) const {
    return translation_m <= max_translation_m && rotation_deg <= max_rotation_deg;
  }
};

PoseDeviation pose_deviation(const geo::SE3& a_cw, const geo::SE3& b_cw);

class PoseGuardRules {
 public:
  explicit PoseGuardRules(PoseGuardConfig config) : config_(config) {}
  // The solved pose left the prediction by more than either threshold.
  [[nodiscard]] bool is_jump(const PoseDeviation& d) const;
  // Enough of the inliers lie near objects to blame the jump on them.
  [[nodiscard]] bool blames_suspects(int inliers, int suspect_inliers) const;
  // The solve without suspects replaces the jumped pose.
  [[nodiscard]] bool accepts_resolve(const PoseDeviation& before, const PoseDeviation& after,
                                     int inliers_after, int min_inliers) const;
  // A frame that jumped may still become a keyframe: its inliers are running out
  // (keyframe_below_reference_share of the reference keyframe's tracked points).
  [[nodiscard]] bool keyframe_despite_jump(int inliers, int reference_tracked) const;
  [[nodiscard]] const PoseGuardConfig& config() const { return config_; }

 private:
  // Deviation in units of the thresholds, so translation and rotation add up.
  [[nodiscard]] double normalized(const PoseDeviation& d) const;
  PoseGuardConfig config_;
};

}  // namespace sp::track
