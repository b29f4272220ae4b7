#pragma once
// A TUM RGB-D folder (rgb/, depth/, rgb.txt, depth.txt, optional associations.txt, camera.yaml) read
// ahead by a background thread, so disk I/O and decoding never stall tracking.
#include <atomic>
#include <filesystem>
#include <optional>
#include <thread>
#include <vector>

#include "stillpoint/common/bounded_queue.hpp"
#include "stillpoint/common/config_reader.hpp"
#include "stillpoint/io/frame_source.hpp"

namespace sp::io {

struct TumSequenceOptions {
  std::optional<std::filesystem::path> camera_file;  // default: DIR/camera.yaml
  std::size_t prefetch = 8;                          // frames decoded ahead, >= 1
  double max_difference = 0.02;  // s, rgb–depth association window (no associations.txt)
  double depth_offset = 0;       // s, added to depth stamps when associating
  std::size_t max_frames = 0;    // 0 = all
  std::size_t start_frame = 0;   // first associated frame to deliver
  // Niceness of the reader thread. It decodes ahead into the prefetch queue, so it can yield the CPU
  // to tracking and the detector and catch up while they wait: 10 gave +11 % FPS on 2 cores against
  // 0 (docs/dynamic.md, session 23). 0 = the caller's priority.
  int reader_nice = 10;

  // Keys: camera_file, prefetch [1, 1024], max_difference [1e-4, 1] s, depth_offset [-1, 1] s,
  // max_frames, start_frame, reader_nice [0, 19]. A relative camera_file is taken as written (relative to the
  // working dir).
  static TumSequenceOptions from_yaml(const ConfigReader& r);
};

class TumSequence : public FrameSource {
 public:
  // Reads the lists and the camera now (errors are thrown here: sp::InputError / sp::ConfigError), then
  // starts the reader thread.
  explicit TumSequence(const std::filesystem::path& dir, const TumSequenceOptions& options = {});
  ~TumSequence() override;  // stops the reader even mid-sequence

  std::optional<FrameData> next() override;
  [[nodiscard]] std::size_t size_hint() const override { return entries_.size(); }
  [[nodiscard]] const CameraConfig& camera() const override { return camera_; }
  [[nodiscard]] std::size_t skipped_frames() const override { return skipped_.load(); }

  // DIR/groundtruth.txt when it exists.
  [[nodiscard]] std::optional<std::filesystem::path> groundtruth_path() const;
  [[nodiscard]] const std::filesystem::path& directory() const noexcept { return dir_; }

 private:
  struct Entry {
    std::size_t index;
    double rgb_stamp, depth_stamp;
    std::filesystem::path rgb, depth;
  };
  void load_entries(const TumSequenceOptions& options);
  void reader_loop();
  [[nodiscard]] std::optional<FrameData> load(const Entry& e) const;

  std::filesystem::path dir_;
  CameraConfig camera_;
  std::vector<Entry> entries_;
  BoundedQueue<FrameData> queue_;
  std::atomic<bool> stop_{false};
  std::atomic<std::size_t> skipped_{0};
  std::thread reader_;
};

}  // namespace sp::io
