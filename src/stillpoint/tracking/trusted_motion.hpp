#pragma once
// Where the camera went while nothing could be tracked (docs/robustness.md "New maps and merging"): a
// new map is seeded at the pose the last trusted frames' motion carries the camera to over the lost
// frames, not at the last trusted pose itself. A person who fills the view for half a second hides a
// camera that keeps moving (10-20 cm in the crowded rooms); a map seeded where it stood keeps that
// offset in every frame if it never merges.
#include <cstddef>
#include <deque>
#include <optional>

#include "stillpoint/geometry/lie.hpp"

namespace sp::track {

class TrustedMotion {
 public:
  // window: trusted frames whose motion is averaged (>= 2 for any motion; fewer: none).
  // max_frames: the most frames the motion is carried on (a long loss is not one steady motion).
  TrustedMotion(int window, int max_frames) : window_(window), max_frames_(max_frames) {}

  // A trusted pose; one that does not follow the last (a gap, a relocalisation, another map) starts over.
  void add(std::size_t frame_index, const geo::SE3& T_cw);
  // The map's frame moved (a merge): p_new = S * p_old for every pose kept.
  void move_frame(const geo::SE3& S_new_old);
  [[nodiscard]] bool has_pose() const { return !poses_.empty(); }
  // The pose at frame_index by the mean motion per frame over the window, carried on for at most
  // max_frames frames after the last trusted one; without a motion (fewer than 2 poses, a window below
  // 2), the last pose itself; none before the first trusted pose.
  [[nodiscard]] std::optional<geo::SE3> extrapolate(std::size_t frame_index) const;

 private:
  struct Stamped {
    std::size_t index;
    geo::SE3 T_cw;
  };
  int window_;
  int max_frames_;
  std::deque<Stamped> poses_;
};

}  // namespace sp::track
