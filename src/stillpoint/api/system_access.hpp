#pragma once
// What `stillpoint run` needs of a stillpoint::System beyond the public API (not installed, not in
// libstillpoint.so): a system built from the CLI's own configuration (a detector model from the
// command line, oracle boxes, culling masks, run artifacts), frames exactly as a FrameSource delivers
// them (the reader's frame index with its gaps, depth and image path kept), and the pipeline
// underneath for the run's statistics, artifacts and ground-truth checks. Everything else the CLI does
// through the public API. docs/library.md, "The CLI and the API".
#include "stillpoint/io/camera_config.hpp"
#include "stillpoint/io/frame.hpp"
#include "stillpoint/pipeline/slam_system.hpp"
#include "stillpoint/pipeline/system_config.hpp"
#include "stillpoint/stillpoint.hpp"

namespace stillpoint::internal {

class SystemAccess {
 public:
  // Leaves logging as the caller set it (the public constructor applies Config::log_level).
  static System create(const sp::pipeline::SystemConfig& config, const sp::io::CameraConfig& camera,
                       const sp::pipeline::SystemOptions& options);
  // One frame as the source gave it, with the public result (callbacks run as in System::track). A
  // failed stage is not checked here: see pipeline().failed().
  static TrackResult track(System& system, const sp::io::FrameData& frame);
  static sp::pipeline::SlamSystem& pipeline(System& system);
};

}  // namespace stillpoint::internal
