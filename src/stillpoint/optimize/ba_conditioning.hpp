#pragma once
// How well a bundle-adjustment problem pins down each free keyframe, before it is solved.
//
// A keyframe whose shared points crowd into one small patch of its image (a person filling the view,
// the background a strip at the edge) has a pose that BA can slide along a rotation-translation
// valley: the residuals hardly change while the camera centre moves centimetres (seen room209: local
// BA carried such keyframes 4-9 cm off their tracked poses, docs/tracking_precision.md). The pose's
// information from the points it shares with other keyframes, each point marginalised and the other
// keyframes held fixed, gives the camera centre's standard deviation under unit level-0 pixel noise.
#include <cstddef>
#include <vector>

#include "stillpoint/optimize/bundle_adjustment.hpp"

namespace sp::opt {

// Per problem.keyframes entry: the largest standard deviation (m) of the camera centre, from the
// observations of points that at least one other keyframe also observes; infinity when those
// observations leave a direction unconstrained; 0 for fixed keyframes (not evaluated).
// Throws sp::Error for duplicate ids or an observation naming an unknown keyframe or point (as BA).
std::vector<double> keyframe_centre_std(const BAProblem& problem, const CameraModel& camera);

}  // namespace sp::opt
