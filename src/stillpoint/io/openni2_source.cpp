#include "stillpoint/io/openni2_source.hpp"

#include <spdlog/spdlog.h>

#include <cmath>
#include <opencv2/imgproc.hpp>

#include "stillpoint/common/error.hpp"

#ifdef SP_HAVE_OPENNI2
#include <OpenNI.h>
#endif

namespace sp::io {

namespace {

constexpr const char* kNoDevice =
    "no OpenNI2 device found; is the camera plugged in and are its udev rules installed?";

void check_buffer(const void* data, int width, int height, std::size_t stride_bytes, std::size_t row_bytes,
                  const char* what) {
  if (data == nullptr) throw Error(std::string("OpenNI2 ") + what + " frame has no data");
  if (width <= 0 || height <= 0) {
    throw Error(std::string("OpenNI2 ") + what + " frame has size " + std::to_string(width) + "x" +
                std::to_string(height));
  }
  if (stride_bytes < row_bytes) {
    throw Error(std::string("OpenNI2 ") + what + " frame stride " + std::to_string(stride_bytes) +
                " is shorter than a row (" + std::to_string(row_bytes) + " bytes)");
  }
}

}  // namespace

RawColourFrame copy_colour_buffer(const void* data, int width, int height, std::size_t stride_bytes,
                                  std::uint64_t timestamp_us) {
  check_buffer(data, width, height, stride_bytes, static_cast<std::size_t>(width) * 3, "colour");
  RawColourFrame f;
  f.timestamp_us = timestamp_us;
  // cv::Mat does not write through a const pointer: the wrapper is only read (clone).
  f.rgb = cv::Mat(height, width, CV_8UC3, const_cast<void*>(data), stride_bytes).clone();
  return f;
}

RawDepthFrame copy_depth_buffer(const void* data, int width, int height, std::size_t stride_bytes,
                                std::uint64_t timestamp_us, double metres_per_unit) {
  check_buffer(data, width, height, stride_bytes, static_cast<std::size_t>(width) * 2, "depth");
  if (stride_bytes % 2 != 0)
    throw Error("OpenNI2 depth frame stride " + std::to_string(stride_bytes) + " is odd");
  if (!(metres_per_unit > 0) || !std::isfinite(metres_per_unit))
    throw Error("OpenNI2 depth unit must be > 0");
  RawDepthFrame f;
  f.timestamp_us = timestamp_us;
  f.metres_per_unit = metres_per_unit;
  f.depth = cv::Mat(height, width, CV_16UC1, const_cast<void*>(data), stride_bytes).clone();
  return f;
}

FrameData convert_openni_frames(const RawColourFrame& colour, const RawDepthFrame& depth,
                                const CameraConfig& camera, std::size_t index) {
  const int w = camera.intrinsics.width;
  const int h = camera.intrinsics.height;
  if (colour.rgb.empty() || colour.rgb.type() != CV_8UC3) throw Error("OpenNI2: colour frame is not RGB888");
  if (depth.depth.empty() || depth.depth.type() != CV_16UC1)
    throw Error("OpenNI2: depth frame is not 16-bit");
  if (colour.rgb.cols != w || colour.rgb.rows != h || depth.depth.cols != w || depth.depth.rows != h) {
    throw Error("OpenNI2: colour " + std::to_string(colour.rgb.cols) + "x" + std::to_string(colour.rgb.rows) +
                " / depth " + std::to_string(depth.depth.cols) + "x" + std::to_string(depth.depth.rows) +
                " do not match the camera config " + std::to_string(w) + "x" + std::to_string(h));
  }
  FrameData f;
  f.index = index;
  f.stamp = static_cast<double>(colour.timestamp_us) * 1e-6;
  f.depth_stamp = static_cast<double>(depth.timestamp_us) * 1e-6;
  cv::cvtColor(colour.rgb, f.bgr, cv::COLOR_RGB2BGR);
  depth.depth.convertTo(f.depth, CV_32F, depth.metres_per_unit);
  const cv::Mat out_of_range = (f.depth < camera.depth_min) | (f.depth > camera.depth_max);
  f.depth.setTo(0.0f, out_of_range);
  f.rgb_path = "openni2/" + std::to_string(index);
  return f;
}

TimestampPairer::TimestampPairer(double max_difference_s, std::size_t capacity)
    : max_difference_us_(static_cast<std::uint64_t>(std::llround(std::max(0.0, max_difference_s) * 1e6))),
      capacity_(capacity == 0 ? 1 : capacity) {}

void TimestampPairer::reset_if_backwards(std::uint64_t stamp, std::uint64_t& last) {
  if (stamp < last) {
    spdlog::warn("OpenNI2: timestamp went backwards ({} us after {} us): restarting colour/depth pairing",
                 stamp, last);
    dropped_ += colour_.size() + depth_.size();
    colour_.clear();
    depth_.clear();
  }
  last = stamp;
}

void TimestampPairer::add_colour(RawColourFrame frame) {
  if (seen_colour_) reset_if_backwards(frame.timestamp_us, last_colour_);
  seen_colour_ = true;
  last_colour_ = frame.timestamp_us;
  colour_.push_back(std::move(frame));
  if (colour_.size() > capacity_) {
    colour_.pop_front();
    ++dropped_;
  }
}

void TimestampPairer::add_depth(RawDepthFrame frame) {
  if (seen_depth_) reset_if_backwards(frame.timestamp_us, last_depth_);
  seen_depth_ = true;
  last_depth_ = frame.timestamp_us;
  depth_.push_back(std::move(frame));
  if (depth_.size() > capacity_) {
    depth_.pop_front();
    ++dropped_;
  }
}

std::optional<std::pair<RawColourFrame, RawDepthFrame>> TimestampPairer::pop_pair() {
  while (!colour_.empty() && !depth_.empty()) {
    const std::uint64_t c = colour_.front().timestamp_us;
    const std::uint64_t d = depth_.front().timestamp_us;
    const std::uint64_t diff = c > d ? c - d : d - c;
    if (diff <= max_difference_us_) {
      // The nearer of this depth and the next one, when the next is closer to this colour frame.
      if (depth_.size() > 1) {
        const std::uint64_t d2 = depth_[1].timestamp_us;
        const std::uint64_t diff2 = c > d2 ? c - d2 : d2 - c;
        if (diff2 < diff) {
          depth_.pop_front();
          ++dropped_;
          continue;
        }
      }
      std::pair<RawColourFrame, RawDepthFrame> out{std::move(colour_.front()), std::move(depth_.front())};
      colour_.pop_front();
      depth_.pop_front();
      return out;
    }
    // Streams are ordered: the older frame can never find a partner any more.
    if (c < d) {
      colour_.pop_front();
    } else {
      depth_.pop_front();
    }
    ++dropped_;
  }
  return std::nullopt;
}

CameraConfig intrinsics_from_fov(int width, int height, double hfov_rad, double vfov_rad, double fps) {
  if (width <= 0 || height <= 0) throw Error("intrinsics_from_fov: image size must be positive");
  if (!(hfov_rad > 0 && hfov_rad < M_PI) || !(vfov_rad > 0 && vfov_rad < M_PI)) {
    throw Error("intrinsics_from_fov: fields of view must be in (0, pi) radians");
  }
  CameraConfig c;
  auto& k = c.intrinsics;
  k.width = width;
  k.height = height;
  k.fx = 0.5 * width / std::tan(0.5 * hfov_rad);
  k.fy = 0.5 * height / std::tan(0.5 * vfov_rad);
  k.cx = 0.5 * width;
  k.cy = 0.5 * height;
  k.k1 = k.k2 = k.p1 = k.p2 = k.k3 = 0;
  c.depth_factor = 1000;  // OpenNI depth is in millimetres
  c.fps = fps;
  return c;
}

std::unique_ptr<FrameSource> open_openni2_camera(const CameraConfig& camera, const std::string& uri) {
  OpenNI2Options options;
  options.uri = uri;
  options.camera = camera;
  return open_openni2_camera(options);
}

std::unique_ptr<FrameSource> open_openni2_camera(const OpenNI2Options& options) {
  return std::make_unique<OpenNI2Source>(options);
}

#ifdef SP_HAVE_OPENNI2

bool openni2_available() { return true; }

namespace {
std::string oni_error() {
  const char* e = openni::OpenNI::getExtendedError();
  return e != nullptr && *e != '\0' ? std::string(" (") + e + ")" : std::string();
}

void set_mode(openni::VideoStream& stream, int width, int height, int fps, openni::PixelFormat format,
              const char* what) {
  openni::VideoMode mode;
  mode.setResolution(width, height);
  mode.setFps(fps);
  mode.setPixelFormat(format);
  if (stream.setVideoMode(mode) != openni::STATUS_OK) {
    throw Error(std::string("OpenNI2: the device refuses the ") + what + " mode " + std::to_string(width) +
                "x" + std::to_string(height) + "@" + std::to_string(fps) + oni_error());
  }
}
}  // namespace

struct OpenNI2Source::Device {
  openni::Device device;
  openni::VideoStream depth;
  openni::VideoStream colour;
  bool is_file = false;
  ~Device() {
    depth.stop();
    colour.stop();
    depth.destroy();
    colour.destroy();
    device.close();
    openni::OpenNI::shutdown();
  }
};

OpenNI2Source::OpenNI2Source(const OpenNI2Options& options)
    : options_(options), pairer_(options.max_difference) {
  if (openni::OpenNI::initialize() != openni::STATUS_OK) {
    openni::OpenNI::shutdown();
    throw Error(std::string(kNoDevice) + " OpenNI2 failed to start" + oni_error());
  }
  auto dev = std::make_unique<Device>();  // from here on its destructor shuts OpenNI down
  if (options.uri.empty()) {
    openni::Array<openni::DeviceInfo> devices;
    openni::OpenNI::enumerateDevices(&devices);
    if (devices.getSize() == 0) throw Error(kNoDevice);
  }
  if (dev->device.open(options.uri.empty() ? openni::ANY_DEVICE : options.uri.c_str()) != openni::STATUS_OK) {
    throw Error(options.uri.empty() ? std::string(kNoDevice) + oni_error()
                                    : "OpenNI2: cannot open '" + options.uri + "'" + oni_error());
  }
  dev->is_file = dev->device.isFile();
  if (dev->depth.create(dev->device, openni::SENSOR_DEPTH) != openni::STATUS_OK) {
    throw Error("OpenNI2: the device has no depth stream" + oni_error());
  }
  if (dev->colour.create(dev->device, openni::SENSOR_COLOR) != openni::STATUS_OK) {
    throw Error("OpenNI2: the device has no colour stream" + oni_error());
  }
  if (!dev->is_file) {
    set_mode(dev->depth, options.width, options.height, options.fps, openni::PIXEL_FORMAT_DEPTH_1_MM,
             "depth");
    set_mode(dev->colour, options.width, options.height, options.fps, openni::PIXEL_FORMAT_RGB888, "colour");
    if (options.registration) {
      if (!dev->device.isImageRegistrationModeSupported(openni::IMAGE_REGISTRATION_DEPTH_TO_COLOR) ||
          dev->device.setImageRegistrationMode(openni::IMAGE_REGISTRATION_DEPTH_TO_COLOR) !=
              openni::STATUS_OK) {
        spdlog::warn("OpenNI2: depth-to-colour registration not available: depth is NOT registered");
      }
    }
    if (dev->device.setDepthColorSyncEnabled(true) != openni::STATUS_OK) {
      spdlog::warn("OpenNI2: depth/colour frame sync not available; pairing by timestamp only");
    }
  }
  if (dev->depth.start() != openni::STATUS_OK || dev->colour.start() != openni::STATUS_OK) {
    throw Error("OpenNI2: cannot start the streams" + oni_error());
  }
  if (options.camera) {
    camera_ = *options.camera;
  } else {
    camera_ = intrinsics_from_fov(options.width, options.height, dev->colour.getHorizontalFieldOfView(),
                                  dev->colour.getVerticalFieldOfView(), options.fps);
    spdlog::warn("OpenNI2: no camera config, intrinsics from the field of view: fx {:.1f} fy {:.1f}",
                 camera_.intrinsics.fx, camera_.intrinsics.fy);
  }
  const openni::VideoMode cm = dev->colour.getVideoMode();
  if (cm.getResolutionX() != camera_.intrinsics.width || cm.getResolutionY() != camera_.intrinsics.height) {
    throw Error("OpenNI2: the camera config is " + std::to_string(camera_.intrinsics.width) + "x" +
                std::to_string(camera_.intrinsics.height) + " but the device streams " +
                std::to_string(cm.getResolutionX()) + "x" + std::to_string(cm.getResolutionY()));
  }
  spdlog::info("OpenNI2: streaming {}x{} colour and depth{}", cm.getResolutionX(), cm.getResolutionY(),
               dev->is_file ? " from a recording" : "");
  device_ = std::move(dev);
}

OpenNI2Source::~OpenNI2Source() = default;

std::size_t OpenNI2Source::skipped_frames() const { return pairer_.dropped() + bad_frames_; }

std::optional<FrameData> OpenNI2Source::next() {
  const double timeout_s = device_->is_file ? std::min(1.0, options_.frame_timeout) : options_.frame_timeout;
  const int timeout_ms = static_cast<int>(std::max(1.0, timeout_s * 1000.0));
  openni::VideoStream* streams[2] = {&device_->depth, &device_->colour};
  while (true) {
    if (auto pair = pairer_.pop_pair()) {
      try {
        return convert_openni_frames(pair->first, pair->second, camera_, next_index_++);
      } catch (const Error& e) {
        ++bad_frames_;
        spdlog::warn("OpenNI2: skipping a frame: {}", e.what());
        continue;
      }
    }
    int ready = -1;
    const openni::Status st = openni::OpenNI::waitForAnyStream(streams, 2, &ready, timeout_ms);
    if (st != openni::STATUS_OK) {                // STATUS_TIME_OUT or an error
      if (device_->is_file) return std::nullopt;  // end of the recording
      throw Error("OpenNI2: no frame from the camera for " + std::to_string(timeout_s) +
                  " s; was it unplugged?" + oni_error());
    }
    openni::VideoFrameRef frame;
    if (streams[ready]->readFrame(&frame) != openni::STATUS_OK || !frame.isValid()) {
      ++bad_frames_;
      continue;
    }
    try {
      if (ready == 0) {
        const auto format = frame.getVideoMode().getPixelFormat();
        const double unit = format == openni::PIXEL_FORMAT_DEPTH_100_UM ? 1e-4 : 1e-3;
        pairer_.add_depth(copy_depth_buffer(frame.getData(), frame.getWidth(), frame.getHeight(),
                                            static_cast<std::size_t>(frame.getStrideInBytes()),
                                            frame.getTimestamp(), unit));
      } else {
        pairer_.add_colour(copy_colour_buffer(frame.getData(), frame.getWidth(), frame.getHeight(),
                                              static_cast<std::size_t>(frame.getStrideInBytes()),
                                              frame.getTimestamp()));
      }
    } catch (const Error& e) {
      ++bad_frames_;
      spdlog::warn("OpenNI2: dropping a frame: {}", e.what());
    }
  }
}

#else  // built without OpenNI2

bool openni2_available() { return false; }

struct OpenNI2Source::Device {};

OpenNI2Source::OpenNI2Source(const OpenNI2Options& options)
    : options_(options), pairer_(options.max_difference) {
  throw Error("built without OpenNI2: install libopenni2-dev and reconfigure to use a live camera");
}
OpenNI2Source::~OpenNI2Source() = default;
std::size_t OpenNI2Source::skipped_frames() const { return pairer_.dropped() + bad_frames_; }
std::optional<FrameData> OpenNI2Source::next() { return std::nullopt; }

#endif

}  // namespace sp::io
