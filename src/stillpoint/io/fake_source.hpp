#pragma once
// A FrameSource that serves frames held in memory: for tests of anything that consumes frames
// (the pipeline, the live-camera conversion) without touching the disk or a device.
#include <cstddef>
#include <deque>
#include <optional>
#include <vector>

#include "stillpoint/io/frame_source.hpp"

namespace sp::io {

class FakeSource : public FrameSource {
 public:
  // Frames are served in the order given; `skipped` is what skipped_frames() reports.
  explicit FakeSource(CameraConfig camera, std::vector<FrameData> frames = {}, std::size_t skipped = 0);

  // Appends a frame to the end of the queue.
  void push(FrameData frame);
  // Frames not served yet.
  [[nodiscard]] std::size_t remaining() const noexcept { return frames_.size(); }
  // Frames served so far.
  [[nodiscard]] std::size_t served() const noexcept { return served_; }

  std::optional<FrameData> next() override;
  [[nodiscard]] std::size_t size_hint() const override { return total_; }
  [[nodiscard]] const CameraConfig& camera() const override { return camera_; }
  [[nodiscard]] std::size_t skipped_frames() const override { return skipped_; }

 private:
  CameraConfig camera_;
  std::deque<FrameData> frames_;
  std::size_t total_ = 0;
  std::size_t served_ = 0;
  std::size_t skipped_ = 0;
};

// A synthetic frame of the camera's size: a textured colour image (deterministic in `seed`) and a
// constant depth of `depth_m` metres, stamped `stamp` seconds.
FrameData make_synthetic_frame(const CameraConfig& camera, std::size_t index, double stamp,
                               double depth_m = 2.0, unsigned seed = 0);

}  // namespace sp::io
