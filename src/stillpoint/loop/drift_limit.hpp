#pragma once
// How far a loop correction may move a keyframe: odometry drifts with the path travelled, so a
// correction much larger than the drift since the first visit is a look-alike place, not a loop
// (a half-turn symmetric office passes every geometric check; docs/loop_sequences.md).
#include <vector>

#include "stillpoint/geometry/lie.hpp"

namespace sp::loop {

struct DriftLimitConfig {
  bool enabled = true;
  double base_m = 0.3;     // m, allowed with no path travelled
  double base_deg = 10.0;  // deg, the same for rotation
  double ratio = 0.1;      // allowed drift per metre (per degree) travelled
};

struct Motion {
  double metres = 0;
  double degrees = 0;
};

// Path length and total rotation along camera poses (T_cw) in the order they were visited.
Motion travelled(const std::vector<geo::SE3>& poses_cw);
// The camera-centre shift and rotation between two poses of one keyframe (T_cw before and after).
Motion correction(const geo::SE3& before_cw, const geo::SE3& after_cw);
// The largest correction drift can explain after `path`.
Motion allowance(const Motion& path, const DriftLimitConfig& config);
// True when the correction is within the allowance (always, when the limit is disabled).
bool plausible(const Motion& correction, const Motion& path, const DriftLimitConfig& config);

}  // namespace sp::loop
