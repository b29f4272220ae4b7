#pragma once
// Small synthetic RGB-D scenes shared by the optimisation tests.
#include <Eigen/Core>
#include <random>
#include <vector>

#include "stillpoint/geometry/lie.hpp"
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

}  // namespace sp::opt::test
