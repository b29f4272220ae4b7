#pragma once
// Small synthetic RGB-D scenes shared by the optimisation tests.
#include <Eigen/Core>
#include <random>
#include <vector>

#include "stillpoint/geometry/lie.hpp"
#include "stillpoint/optimize/bundle_adjustment.hpp"
#include "stillpoint/optimize/residuals.hpp"

namespace sp::opt::test {

inline CameraModel test_camera() { return CameraModel{500.0, 505.0, 320.0, 240.0, 40.0}; }

// A camera pose T_cw looking roughly along +z of the world, displaced by `index`.
inline geo::SE3 camera_pose(int index) {
  geo::Vec6 xi;
  xi << 0.15 * index, -0.03 * index, 0.05 * index, 0.01 * index, -0.04 * index, 0.02 * index;
  return geo::SE3::exp(xi);
}

inline std::vector<Eigen::Vector3d> random_points(std::mt19937& rng, int count) {
  std::uniform_real_distribution<double> ux(-2.0, 2.0), uy(-1.5, 1.5), uz(3.0, 8.0);
  std::vector<Eigen::Vector3d> pts;
  for (int i = 0; i < count; ++i) {
    // Draws in named steps, last argument first: argument evaluation order is unspecified (GCC goes
    // right to left, clang left to right), so a clang build generated other data and failed.
    const double z = uz(rng);
    const double y = uy(rng);
    pts.emplace_back(ux(rng), y, z);
  }
  return pts;
}

inline geo::Vec6 random_xi(std::mt19937& rng, double sigma_t, double sigma_r) {
  std::normal_distribution<double> n(0.0, 1.0);
  geo::Vec6 xi;
  for (int i = 0; i < 3; ++i) xi[i] = sigma_t * n(rng);
  for (int i = 3; i < 6; ++i) xi[i] = sigma_r * n(rng);
  return xi;
}

// Position error (metres) and rotation error (radians) between two T_cw.
inline double position_error(const geo::SE3& a, const geo::SE3& b) {
  return (a.inverse().translation() - b.inverse().translation()).norm();
}
inline double rotation_error(const geo::SE3& a, const geo::SE3& b) {
  return geo::rotation_angle(a.rotation() * b.rotation().transpose());
}

// A local-BA-like scene: keyframes along a slowly turning path, the first `fixed_keyframes` of them
// fixed (as the keyframes outside ORB-SLAM's local window), the next `free_keyframes` free. Each
// point is anchored in a random keyframe and seen by the keyframes within `span` of it that it
// projects into, so points seen only by fixed keyframes, only by free ones, and by both occur.
struct BASceneSpec {
  int free_keyframes = 20;
  int fixed_keyframes = 20;
  int points = 2500;
  int span = 3;
  double stereo_ratio = 0.9;   // share of observations with a virtual right coordinate
  double outlier_ratio = 0.0;  // share of observations moved by 20-40 px (gross outliers)
  double pixel_noise = 1.0;    // px at pyramid level 0, scaled by the level's sigma
  double pose_noise_t = 0.02, pose_noise_r = 0.01;  // start perturbation of the free poses (m, rad)
  double point_noise = 0.03;                        // start perturbation of the points (m)
  unsigned seed = 1;
};

struct BAScene {
  BAProblem truth;          // exact poses and points, the noisy observations
  BAProblem problem;        // the perturbed start
  std::vector<bool> gross;  // per observation
};

inline BAScene make_ba_scene(const BASceneSpec& spec) {
  std::mt19937 rng(spec.seed);
  std::normal_distribution<double> n01(0.0, 1.0);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  const CameraModel cam = test_camera();
  BAScene s;
  const int nk = spec.fixed_keyframes + spec.free_keyframes;
  std::vector<geo::SE3> T_wc;
  for (int k = 0; k < nk; ++k) {
    geo::Vec6 xi;
    xi << 0.08 * k, 0.02 * std::sin(0.3 * k), 0.01 * k, 0.005 * std::sin(0.2 * k), 0.02 * k, 0.0;
    T_wc.push_back(geo::SE3::exp(xi));
    s.truth.keyframes.push_back(
        {static_cast<std::uint64_t>(1000 + k), T_wc.back().inverse(), k < spec.fixed_keyframes});
  }
  for (int i = 0; i < spec.points; ++i) {
    const int anchor = static_cast<int>(u01(rng) * nk) % nk;
    const double z = 2.0 + 6.0 * u01(rng);
    const double v = 20.0 + 440.0 * u01(rng);
    const double u = 20.0 + 600.0 * u01(rng);
    const Eigen::Vector3d p_c((u - cam.cx) * z / cam.fx, (v - cam.cy) * z / cam.fy, z);
    const auto id = static_cast<std::uint64_t>(5 * i + 3);
    s.truth.points.push_back({id, T_wc[static_cast<std::size_t>(anchor)] * p_c});
    for (int k = std::max(0, anchor - spec.span); k <= std::min(nk - 1, anchor + spec.span); ++k) {
      const BAKeyframe& kf = s.truth.keyframes[static_cast<std::size_t>(k)];
      const Eigen::Vector3d pc = kf.T_cw * s.truth.points.back().p_w;
      if (pc.z() <= 0.1) continue;
      const Eigen::Vector3d proj = project_stereo(cam, pc);
      if (proj.x() < 5 || proj.x() > 635 || proj.y() < 5 || proj.y() > 475) continue;
      BAObservation o;
      o.keyframe_id = kf.id;
      o.point_id = id;
      const double sigma = std::pow(1.2, static_cast<int>(u01(rng) * 4));
      o.inv_sigma2 = 1.0 / (sigma * sigma);
      const double nu = n01(rng);
      const double nv = n01(rng);
      o.uv = proj.head<2>() + spec.pixel_noise * sigma * Eigen::Vector2d(nu, nv);
      const double nr = n01(rng);
      if (u01(rng) < spec.stereo_ratio) o.u_right = proj.z() + spec.pixel_noise * sigma * nr;
      const bool gross = u01(rng) < spec.outlier_ratio;
      if (gross) {
        // One draw per statement (operand evaluation order is unspecified, see random_points).
        const double su = u01(rng) < 0.5 ? -1.0 : 1.0;
        const double du = su * (20.0 + 20.0 * u01(rng));
        const double sv = u01(rng) < 0.5 ? -1.0 : 1.0;
        const double dv = sv * (20.0 + 20.0 * u01(rng));
        o.uv += Eigen::Vector2d(du, dv);
        if (o.u_right >= 0) o.u_right += du;
      }
      s.truth.observations.push_back(o);
      s.gross.push_back(gross);
    }
  }
  s.problem = s.truth;
  for (BAKeyframe& kf : s.problem.keyframes) {
    if (!kf.fixed) kf.T_cw = geo::SE3::exp(random_xi(rng, spec.pose_noise_t, spec.pose_noise_r)) * kf.T_cw;
  }
  for (BAPoint& p : s.problem.points) {
    const double dz = n01(rng);
    const double dy = n01(rng);
    p.p_w += spec.point_noise * Eigen::Vector3d(n01(rng), dy, dz);
  }
  return s;
}

}  // namespace sp::opt::test
