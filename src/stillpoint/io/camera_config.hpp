#pragma once
// Camera of an RGB-D sequence: intrinsics, lens distortion and the depth encoding, read from the
// camera.yaml that every sequence folder carries (or a preset in config/camera/).
#include <filesystem>

#include "stillpoint/common/config_reader.hpp"
#include "stillpoint/geometry/camera.hpp"

namespace sp::io {

struct CameraConfig {
  geo::CameraIntrinsics intrinsics;
  double depth_factor = 5000;  // raw 16-bit depth value per metre, (0, 1e6]
  double fps = 30;             // nominal frame rate in Hz, (0, 1000]
  double depth_min = 0.1;      // metres; closer readings are treated as invalid, [0, 100]
  double depth_max = 8.0;      // metres; farther readings are treated as invalid, (depth_min, 1000]

  // Required: width height fx fy cx cy k1 k2 p1 p2 k3 depth_factor fps; optional: depth_min depth_max.
  // Does not call finish(): the caller decides whether other keys may live beside these.
  static CameraConfig from_yaml(const ConfigReader& r);
};

// The camera settings formats load_camera_config understands.
enum class CameraFormat {
  StillPoint,  // our camera.yaml (keys above)
  OrbSlam,     // ORB-SLAM2 / ORB-SLAM3 settings: `%YAML:1.0`, Camera.fx or Camera1.fx (3 >= 1.0), ...
  Stella,      // stella_vslam / OpenVSLAM: a `Camera:` map (or Camera.* keys) with model and setup
};

// Which format a settings file is written in (by its keys; ORB-SLAM's `%YAML:1.0` first line is
// accepted). Throws a ConfigError for unreadable YAML.
CameraFormat detect_camera_format(const std::filesystem::path& file);

// Reads a camera file in any CameraFormat. Our camera.yaml is strict: a missing key, an unknown key or a
// value out of range is a ConfigError naming the file, the key and the line. ORB-SLAM and stella_vslam
// files carry many other settings (ORB, viewer, tracking) that are ignored; from them we read the
// pinhole intrinsics and radial-tangential distortion (k1 k2 p1 p2 [k3]), image size, fps and the depth
// map factor (ORB-SLAM: DepthMapFactor or RGBD.DepthMapFactor; stella: depthmap_factor under
// Preprocessing, Tracking or Camera). Other camera models (fisheye, Kannala-Brandt, equirectangular) and
// a missing depth factor are ConfigErrors.
CameraConfig load_camera_config(const std::filesystem::path& file);

}  // namespace sp::io
