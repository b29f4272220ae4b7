#include "stillpoint/io/camera_config.hpp"

#include <fstream>
#include <optional>
#include <sstream>
#include <utility>

namespace sp::io {

CameraConfig CameraConfig::from_yaml(const ConfigReader& r) {
  CameraConfig c;
  auto& k = c.intrinsics;
  k.width = r.require<int>("width", 1, 100000);
  k.height = r.require<int>("height", 1, 100000);
  k.fx = r.require<double>("fx", 1e-6, 1e6);
  k.fy = r.require<double>("fy", 1e-6, 1e6);
  // The principal point may sit off-centre but never outside the image.
  k.cx = r.require<double>("cx", 0.0, static_cast<double>(k.width));
  k.cy = r.require<double>("cy", 0.0, static_cast<double>(k.height));
  k.k1 = r.require<double>("k1", -100.0, 100.0);
  k.k2 = r.require<double>("k2", -100.0, 100.0);
  k.p1 = r.require<double>("p1", -1.0, 1.0);
  k.p2 = r.require<double>("p2", -1.0, 1.0);
  k.k3 = r.require<double>("k3", -100.0, 100.0);
  c.depth_factor = r.require<double>("depth_factor", 1e-6, 1e6);
  c.fps = r.require<double>("fps", 1e-3, 1000.0);
  r.read("depth_min", c.depth_min, 0.0, 100.0);
  r.read("depth_max", c.depth_max, 0.0, 1000.0);
  if (c.depth_max <= c.depth_min) {
    r.fail(r.has("depth_max") ? "depth_max" : "depth_min", "depth_max must be greater than depth_min");
  }
  return c;
}

namespace {

// The file's text with ORB-SLAM's OpenCV header `%YAML:1.0` (not valid YAML 1.2) turned into a comment,
// so line numbers in errors stay those of the file.
ConfigReader read_settings(const std::filesystem::path& file) {
  if (!std::filesystem::exists(file)) throw ConfigError(file.string(), 0, "(file)", "file not found");
  std::ifstream in(file, std::ios::binary);
  if (!in) throw ConfigError(file.string(), 0, "(file)", "cannot open the file");
  std::stringstream text;
  text << in.rdbuf();
  std::string s = text.str();
  if (s.rfind("%YAML:", 0) == 0) s.insert(0, "# ");
  return ConfigReader::from_string(s, file.string());
}

// A key written either as a dotted literal (`Camera.fx: 1`, OpenCV style) or nested (`Camera:\n  fx: 1`).
class DottedKeys {
 public:
  explicit DottedKeys(const ConfigReader& root) : root_(root) {}
  [[nodiscard]] bool has(const std::string& key) const { return where(key).has_value(); }
  template <typename T>
  T require(const std::string& key, T lo, T hi) const {
    const auto w = where(key);
    if (!w) root_.fail(key, "missing required key");
    return w->first.template require<T>(w->second, lo, hi);
  }
  template <typename T>
  T get(const std::string& key, T fallback, T lo, T hi) const {
    return has(key) ? require<T>(key, lo, hi) : fallback;
  }
  // A ConfigError naming the key where it is written (its line, nested or dotted).
  [[noreturn]] void fail(const std::string& key, const std::string& what) const {
    const auto w = where(key);
    if (w) w->first.fail(w->second, what);
    root_.fail(key, what);
  }
  [[nodiscard]] std::string text(const std::string& key) const {
    const auto w = where(key);
    return w ? w->first.template require<std::string>(w->second) : std::string();
  }

 private:
  [[nodiscard]] std::optional<std::pair<ConfigReader, std::string>> where(const std::string& key) const {
    if (root_.has(key)) return std::make_pair(root_, key);
    const auto dot = key.find('.');
    if (dot == std::string::npos || !root_.has(key.substr(0, dot))) return std::nullopt;
    const std::string outer = key.substr(0, dot), inner = key.substr(dot + 1);
    try {
      const ConfigReader section = root_.section(outer);
      if (section.has(inner)) return std::make_pair(section, inner);
    } catch (const ConfigError&) {  // `outer` is a scalar: no nested key
    }
    return std::nullopt;
  }
  const ConfigReader& root_;
};

CameraFormat format_of(const ConfigReader& r) {
  const DottedKeys k(r);
  if (k.has("Camera.model") || k.has("Camera.setup")) return CameraFormat::Stella;
  if (k.has("Camera.fx") || k.has("Camera1.fx")) return CameraFormat::OrbSlam;
  return CameraFormat::StillPoint;
}

void read_distortion(const DottedKeys& k, const std::string& prefix, geo::CameraIntrinsics& K) {
  K.k1 = k.get(prefix + "k1", 0.0, -100.0, 100.0);
  K.k2 = k.get(prefix + "k2", 0.0, -100.0, 100.0);
  K.p1 = k.get(prefix + "p1", 0.0, -1.0, 1.0);
  K.p2 = k.get(prefix + "p2", 0.0, -1.0, 1.0);
  K.k3 = k.get(prefix + "k3", 0.0, -100.0, 100.0);
}

void read_pinhole(const DottedKeys& k, const std::string& prefix, geo::CameraIntrinsics& K) {
  K.fx = k.require(prefix + "fx", 1e-6, 1e6);
  K.fy = k.require(prefix + "fy", 1e-6, 1e6);
  K.cx = k.require(prefix + "cx", 0.0, static_cast<double>(K.width));
  K.cy = k.require(prefix + "cy", 0.0, static_cast<double>(K.height));
}

// ORB-SLAM2 (Camera.fx ... DepthMapFactor) and ORB-SLAM3 (File.version "1.0": Camera1.fx ...,
// RGBD.DepthMapFactor; older ORB-SLAM3 files use ORB-SLAM2's keys plus Camera.type).
CameraConfig from_orbslam(const ConfigReader& r) {
  const DottedKeys k(r);
  const std::string type = k.text("Camera.type");
  if (!type.empty() && type != "PinHole") {
    k.fail("Camera.type", "camera model '" + type + "' is not supported (only PinHole)");
  }
  CameraConfig c;
  auto& K = c.intrinsics;
  K.width = k.require("Camera.width", 1, 100000);
  K.height = k.require("Camera.height", 1, 100000);
  const std::string prefix = k.has("Camera1.fx") ? "Camera1." : "Camera.";
  read_pinhole(k, prefix, K);
  read_distortion(k, prefix, K);
  c.fps = k.get("Camera.fps", 30.0, 1e-3, 1000.0);
  if (k.has("RGBD.DepthMapFactor")) {
    c.depth_factor = k.require("RGBD.DepthMapFactor", 1e-6, 1e6);
  } else {
    c.depth_factor = k.require("DepthMapFactor", 1e-6, 1e6);
  }
  return c;
}

// stella_vslam / OpenVSLAM: Camera.{model, setup, fx, fy, cx, cy, k1, k2, p1, p2, k3, fps, cols, rows}
// (nested or dotted) and depthmap_factor under Preprocessing (stella_vslam), Tracking (older stella),
// Camera, or at the top level.
CameraConfig from_stella(const ConfigReader& r) {
  const DottedKeys k(r);
  const std::string model = k.text("Camera.model");
  if (!model.empty() && model != "perspective") {
    k.fail("Camera.model", "camera model '" + model + "' is not supported (only perspective)");
  }
  const std::string setup = k.text("Camera.setup");
  if (!setup.empty() && setup != "RGBD") {
    k.fail("Camera.setup", "setup '" + setup + "' is not an RGB-D camera (expected RGBD)");
  }
  CameraConfig c;
  auto& K = c.intrinsics;
  K.width = k.require("Camera.cols", 1, 100000);
  K.height = k.require("Camera.rows", 1, 100000);
  read_pinhole(k, "Camera.", K);
  read_distortion(k, "Camera.", K);
  c.fps = k.get("Camera.fps", 30.0, 1e-3, 1000.0);
  bool found = false;
  for (const char* key : {"Preprocessing.depthmap_factor", "Tracking.depthmap_factor",
                          "Camera.depthmap_factor", "depthmap_factor"}) {
    if (k.has(key)) {
      c.depth_factor = k.require(key, 1e-6, 1e6);
      found = true;
      break;
    }
  }
  if (!found) r.fail("Preprocessing.depthmap_factor", "missing required key (the depth image scale)");
  return c;
}

}  // namespace

CameraFormat detect_camera_format(const std::filesystem::path& file) {
  return format_of(read_settings(file));
}

CameraConfig load_camera_config(const std::filesystem::path& file) {
  const ConfigReader r = read_settings(file);
  switch (format_of(r)) {
    case CameraFormat::OrbSlam:
      return from_orbslam(r);
    case CameraFormat::Stella:
      return from_stella(r);
    case CameraFormat::StillPoint:
      break;
  }
  CameraConfig c = CameraConfig::from_yaml(r);
  r.finish();
  return c;
}

}  // namespace sp::io
