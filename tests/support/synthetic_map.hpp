#pragma once
// Small generated maps for the tracker, local mapper and loop closer tests: scene points with random
// descriptors (256 random bits: two rows differ in ~128 bits, so every point is unique to the
// matchers), features made of their exact projections with depth and virtual stereo, and keyframes
// placed in a Map at an *estimated* pose that may differ from the true one (drift). A keyframe's new
// points are back-projected from its estimated pose, as an RGB-D keyframe creates them.
#include <Eigen/Geometry>
#include <cmath>
#include <optional>
#include <random>
#include <unordered_map>
#include <vector>

#include "stillpoint/geometry/camera.hpp"
#include "stillpoint/map/map.hpp"

namespace sp::testing {

struct SyntheticScene {
  std::vector<Eigen::Vector3d> points;
  cv::Mat descriptors;  // one row per point
};

inline cv::Mat random_descriptors(int n, std::mt19937& rng) {
  std::uniform_int_distribution<int> byte(0, 255);
  cv::Mat d(n, 32, CV_8U);
  for (int i = 0; i < n; ++i)
    for (int b = 0; b < 32; ++b) d.at<std::uint8_t>(i, b) = static_cast<std::uint8_t>(byte(rng));
  return d;
}

// Points on the inside of a vertical cylinder (axis y through the origin): a room seen by a camera
// that turns on the spot or walks a circle inside it, so the path can come back to where it started.
inline SyntheticScene make_cylinder_scene(int n, double radius, double half_height, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> angle(0.0, 2.0 * M_PI), y(-half_height, half_height),
      r(radius - 0.3, radius + 0.3);
  SyntheticScene s;
  for (int i = 0; i < n; ++i) {
    const double a = angle(rng), h = y(rng), rr = r(rng);
    s.points.emplace_back(rr * std::sin(a), h, rr * std::cos(a));
  }
  s.descriptors = random_descriptors(n, rng);
  return s;
}

// Points in a slab in front of a camera at the origin looking down +z (x, y spread, z in [z0, z1]).
inline SyntheticScene make_slab_scene(int n, double half_width, double half_height, double z0, double z1,
                                      unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> x(-half_width, half_width), y(-half_height, half_height), z(z0, z1);
  SyntheticScene s;
  for (int i = 0; i < n; ++i) {
    const double a = x(rng), b = y(rng), c = z(rng);
    s.points.emplace_back(a, b, c);
  }
  s.descriptors = random_descriptors(n, rng);
  return s;
}

// A camera at `centre` (world) looking along `yaw` radians about +y (0 = +z), y down as the images.
inline geo::SE3 camera_pose(const Eigen::Vector3d& centre, double yaw) {
  const Eigen::Matrix3d R_wc = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY()).toRotationMatrix();
  geo::SE3 T_wc(Eigen::Quaterniond(R_wc), centre);
  return T_wc.inverse();
}

struct Observation {
  map::FeatureSet features;
  std::vector<int> rows;  // per feature: the scene point it shows
};

// The scene seen from T_cw: exact projections at level 0, depth and virtual stereo for each point
// nearer than depth_limit (farther ones are features without a depth reading).
inline Observation observe(const SyntheticScene& s, const geo::SE3& T_cw, const geo::CameraIntrinsics& cam,
                           double bf, double depth_limit = 100.0) {
  Observation o;
  for (std::size_t i = 0; i < s.points.size(); ++i) {
    const Eigen::Vector3d p = T_cw * s.points[i];
    if (p.z() < 0.5) continue;
    const Eigen::Vector2d uv = cam.project(p);
    if (uv.x() < 20 || uv.y() < 20 || uv.x() > cam.width - 20 || uv.y() > cam.height - 20) continue;
    o.features.keypoints.emplace_back(static_cast<float>(uv.x()), static_cast<float>(uv.y()), 31.f, 0.f, 1.f,
                                      0);
    const bool has_depth = p.z() < depth_limit;
    o.features.depth.push_back(has_depth ? static_cast<float>(p.z()) : -1.f);
    o.features.u_right.push_back(has_depth ? static_cast<float>(uv.x() - bf / p.z()) : -1.f);
    o.rows.push_back(static_cast<int>(i));
  }
  o.features.descriptors = cv::Mat(static_cast<int>(o.rows.size()), 32, CV_8U);
  for (std::size_t k = 0; k < o.rows.size(); ++k)
    s.descriptors.row(o.rows[k]).copyTo(o.features.descriptors.row(static_cast<int>(k)));
  return o;
}

// Builds a map keyframe by keyframe. A keyframe observes the map point of a scene point made by one
// of the previous `window` keyframes (as tracking would match it); otherwise it makes a new point
// from its own (estimated) pose, so a path that comes back after more than `window` keyframes sees
// the old place as new points: an unclosed loop. Features without depth (beyond depth_limit) get no
// point, as in an RGB-D keyframe before triangulation.
class SyntheticMapBuilder {
 public:
  SyntheticMapBuilder(map::Map& map, const SyntheticScene& scene, geo::CameraIntrinsics cam, double bf,
                      std::size_t window, double depth_limit = 100.0)
      : map_(map), scene_(scene), cam_(cam), bf_(bf), window_(window), depth_limit_(depth_limit) {}

  map::KeyframeId add(const geo::SE3& T_cw_true, const geo::SE3& T_cw_est) {
    const Observation o = observe(scene_, T_cw_true, cam_, bf_, depth_limit_);
    map::MapView view = map_.view();
    map::Keyframe kf;
    kf.frame_index = count_;
    kf.stamp = static_cast<double>(count_) / 30.0;
    kf.T_cw = T_cw_est;
    kf.features = o.features;
    kf.index = map::make_feature_grid(kf.features.keypoints, cam_.width, cam_.height);
    const map::KeyframeId kid = view.add_keyframe(std::move(kf));
    const geo::SE3 T_wc_est = T_cw_est.inverse();
    for (std::size_t i = 0; i < o.rows.size(); ++i) {
      if (o.features.depth[i] <= 0) continue;
      const int row = o.rows[i];
      map::PointId pid = map::kNoPoint;
      if (const auto it = latest_.find(row); it != latest_.end() && count_ - it->second.second <= window_)
        pid = it->second.first;
      if (pid == map::kNoPoint || view.point(pid) == nullptr || view.point(pid)->bad) {
        map::MapPoint p;
        p.position = T_wc_est * (T_cw_true * scene_.points[static_cast<std::size_t>(row)]);
        p.descriptor = o.features.descriptors.row(static_cast<int>(i)).clone();
        p.reference = kid;
        p.first_keyframe = kid;
        pid = view.add_point(std::move(p));
        latest_[row] = {pid, count_};
        row_of_[pid] = row;
      }
      view.add_observation(pid, kid, static_cast<int>(i));
    }
    // Covisibility and spanning-tree parent as local mapping sets them when the keyframe arrives
    // (the parent is the strongest earlier keyframe).
    view.update_connections(kid);
    keyframes_.push_back(kid);
    ++count_;
    return kid;
  }

  // Descriptors, viewing ranges and final covisibility once every keyframe is in.
  void finish(const map::ScalePyramid& pyramid) {
    map::MapView view = map_.view();
    for (const auto& [pid, row] : row_of_) {
      view.update_point_descriptor(pid);
      view.update_point_normal_and_depth(pid, pyramid);
    }
    for (map::KeyframeId k : keyframes_) view.update_connections(k);
  }

  [[nodiscard]] const std::vector<map::KeyframeId>& keyframes() const { return keyframes_; }
  // The scene point a map point stands for.
  [[nodiscard]] std::optional<int> row_of(map::PointId pid) const {
    const auto it = row_of_.find(pid);
    return it == row_of_.end() ? std::nullopt : std::optional<int>(it->second);
  }

 private:
  map::Map& map_;
  const SyntheticScene& scene_;
  geo::CameraIntrinsics cam_;
  double bf_;
  std::size_t window_;
  double depth_limit_;
  std::size_t count_ = 0;
  std::unordered_map<int, std::pair<map::PointId, std::size_t>> latest_;  // row -> point, its keyframe
  std::unordered_map<map::PointId, int> row_of_;
  std::vector<map::KeyframeId> keyframes_;
};

}  // namespace sp::testing
