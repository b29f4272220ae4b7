#include "stillpoint/io/camera_config.hpp"

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

CameraConfig load_camera_config(const std::filesystem::path& file) {
  const ConfigReader r = ConfigReader::from_file(file);
  CameraConfig c = CameraConfig::from_yaml(r);
  r.finish();
  return c;
}

}  // namespace sp::io
