#pragma once
// stillpoint::System's state (not installed): shared by the public API (system.cpp) and the CLI's
// internal access (system_access.cpp), so both track frames through the same code.
#include <cstddef>
#include <functional>
#include <memory>
#include <optional>

#include "stillpoint/io/camera_config.hpp"
#include "stillpoint/io/frame.hpp"
#include "stillpoint/pipeline/slam_system.hpp"
#include "stillpoint/stillpoint.hpp"

namespace stillpoint {

// Hidden: a nested class takes System's default visibility, and libstillpoint.so exports only the API.
struct __attribute__((visibility("hidden"))) System::Impl {
  sp::io::CameraConfig camera;
  std::unique_ptr<sp::pipeline::SlamSystem> system;
  std::function<void(const KeyframeEvent&)> on_keyframe;
  std::function<void(const LoopClosureEvent&)> on_loop;
  std::size_t loops_reported = 0;
  std::size_t frames = 0;
  std::size_t index = 0;
  bool shut_down = false;
  std::optional<double> last_stamp;

  // Tracks one frame as the pipeline takes it (depth in metres, range applied) and runs the
  // callbacks. Does not check for a failed stage: the caller decides when to.
  TrackResult track(const sp::io::FrameData& frame);
  void report_loops();
};

}  // namespace stillpoint
