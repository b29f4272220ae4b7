#pragma once
// A live RGB-D camera through OpenNI2 (Kinect v1, Xtion, Astra, ...) as a FrameSource: 640x480 at
// 30 Hz, depth registered to colour (IMAGE_REGISTRATION_DEPTH_TO_COLOR), colour and depth paired by
// timestamp. OpenNI2 reports only fields of view, so the intrinsics come from a CameraConfig (a
// calibrated camera.yaml); intrinsics_from_fov() gives a rough pinhole model when there is none.
//
// The device-independent part (copying OpenNI buffers, depth mm -> metres, RGB -> BGR, µs -> s,
// pairing colour and depth by timestamp) is pure code below, tested without a device.
#include <cstddef>
#include <cstdint>
#include <deque>
#include <memory>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <utility>

#include "stillpoint/io/frame_source.hpp"

namespace sp::io {

// One colour frame as the device gave it: RGB888, device clock in microseconds.
struct RawColourFrame {
  std::uint64_t timestamp_us = 0;
  cv::Mat rgb;  // CV_8UC3, R G B byte order
};

// One depth frame: 16-bit depth in `metres_per_unit` steps (OpenNI DEPTH_1_MM: 0.001), 0 = no reading.
struct RawDepthFrame {
  std::uint64_t timestamp_us = 0;
  cv::Mat depth;  // CV_16UC1
  double metres_per_unit = 0.001;
};

// Copies a device buffer (rows `stride_bytes` apart) into an owned frame. Throws sp::Error on a null
// buffer, a non-positive size or a stride shorter than a row.
RawColourFrame copy_colour_buffer(const void* data, int width, int height, std::size_t stride_bytes,
                                  std::uint64_t timestamp_us);
RawDepthFrame copy_depth_buffer(const void* data, int width, int height, std::size_t stride_bytes,
                                std::uint64_t timestamp_us, double metres_per_unit = 0.001);

// Converts a colour/depth pair into what the pipeline consumes: BGR colour, depth in metres with
// readings outside [camera.depth_min, camera.depth_max] set to 0, stamps in seconds. Throws
// sp::Error when either image is empty, of the wrong type, or not camera.intrinsics' size.
FrameData convert_openni_frames(const RawColourFrame& colour, const RawDepthFrame& depth,
                                const CameraConfig& camera, std::size_t index);

// Pairs two timestamp-ordered streams: a colour and a depth frame form a pair when their stamps differ
// by at most max_difference. A frame that can no longer be paired (the other stream has moved past
// it) is dropped and counted; a stamp that goes backwards (device restart) clears both buffers.
class TimestampPairer {
 public:
  explicit TimestampPairer(double max_difference_s = 0.02, std::size_t capacity = 8);

  void add_colour(RawColourFrame frame);
  void add_depth(RawDepthFrame frame);
  // The oldest complete pair, if any.
  std::optional<std::pair<RawColourFrame, RawDepthFrame>> pop_pair();

  [[nodiscard]] std::size_t dropped() const noexcept { return dropped_; }
  [[nodiscard]] std::size_t pending_colour() const noexcept { return colour_.size(); }
  [[nodiscard]] std::size_t pending_depth() const noexcept { return depth_.size(); }

 private:
  void reset_if_backwards(std::uint64_t stamp, std::uint64_t& last);
  std::uint64_t max_difference_us_;
  std::size_t capacity_;
  std::deque<RawColourFrame> colour_;
  std::deque<RawDepthFrame> depth_;
  std::uint64_t last_colour_ = 0, last_depth_ = 0;
  bool seen_colour_ = false, seen_depth_ = false;
  std::size_t dropped_ = 0;
};

// A pinhole model from fields of view (radians): fx = (width / 2) / tan(hfov / 2), principal point at
// the centre, no distortion, depth in millimetres. A rough start, not a calibration.
CameraConfig intrinsics_from_fov(int width, int height, double hfov_rad, double vfov_rad, double fps = 30);

struct OpenNI2Options {
  std::string uri;                     // device URI or a recorded .oni file; empty = the first device found
  std::optional<CameraConfig> camera;  // intrinsics; absent = derived from the device's FOV
  int width = 640;                     // pixels
  int height = 480;                    // pixels
  int fps = 30;                        // Hz
  bool registration = true;            // IMAGE_REGISTRATION_DEPTH_TO_COLOR
  double max_difference = 0.02;        // s, colour/depth pairing window
  double frame_timeout = 5.0;          // s without any frame before next() gives up with an sp::Error
};

class OpenNI2Source : public FrameSource {
 public:
  // Opens and starts the device now. Throws sp::Error when OpenNI2 cannot start, no device is found
  // or the device refuses the 640x480@30 modes; in a build without OpenNI2 it always throws.
  explicit OpenNI2Source(const OpenNI2Options& options);
  ~OpenNI2Source() override;

  // Blocks until the next colour/depth pair. Throws sp::Error when no frame arrives within
  // frame_timeout (camera unplugged); returns nullopt at the end of a recorded .oni file.
  std::optional<FrameData> next() override;
  [[nodiscard]] std::size_t size_hint() const override { return 0; }
  [[nodiscard]] const CameraConfig& camera() const override { return camera_; }
  [[nodiscard]] std::size_t skipped_frames() const override;

  struct Device;  // OpenNI objects (defined only where OpenNI2 is compiled in)

 private:
  std::unique_ptr<Device> device_;
  CameraConfig camera_;
  OpenNI2Options options_;
  TimestampPairer pairer_;
  std::size_t next_index_ = 0;
  std::size_t bad_frames_ = 0;
};

// True when this build links OpenNI2.
bool openni2_available();

// The factory `stillpoint run --camera openni2` uses: intrinsics from `camera`, 640x480@30, registered
// depth. Throws sp::Error "no OpenNI2 device found; is the camera plugged in and are its udev rules
// installed?" when there is no device.
std::unique_ptr<FrameSource> open_openni2_camera(const CameraConfig& camera, const std::string& uri = "");
std::unique_ptr<FrameSource> open_openni2_camera(const OpenNI2Options& options);

}  // namespace sp::io
