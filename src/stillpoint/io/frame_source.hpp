#pragma once
// Anything that yields RGB-D frames in time order: a TUM folder, a live camera, a test fixture.
#include <cstddef>
#include <optional>

#include "stillpoint/io/camera_config.hpp"
#include "stillpoint/io/frame.hpp"

namespace sp::io {

class FrameSource {
 public:
  FrameSource() = default;
  FrameSource(const FrameSource&) = delete;
  FrameSource& operator=(const FrameSource&) = delete;
  virtual ~FrameSource();

  // The next frame, or nullopt at the end of the sequence.
  virtual std::optional<FrameData> next() = 0;
  // Frames expected in total (0 when unknown, e.g. live).
  [[nodiscard]] virtual std::size_t size_hint() const = 0;
  [[nodiscard]] virtual const CameraConfig& camera() const = 0;
  // Frames dropped so far because an image was missing or unreadable.
  [[nodiscard]] virtual std::size_t skipped_frames() const = 0;
};

}  // namespace sp::io
