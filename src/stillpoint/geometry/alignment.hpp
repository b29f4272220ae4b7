#pragma once
// Closed-form least-squares alignment of corresponding 3-D points (Horn / Umeyama).
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <vector>

namespace sp::geo {

// dst ≈ scale * R * src + t
struct Similarity3 {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  double scale = 1.0;
  [[nodiscard]] Eigen::Vector3d apply(const Eigen::Vector3d& p) const { return scale * (R * p) + t; }
};

// Needs at least 3 non-collinear pairs; with_scale=false gives the rigid (SE(3)) solution.
// Throws sp::Error when the sizes differ or fewer than 3 pairs are given.
Similarity3 align_umeyama(const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst,
                          bool with_scale);

}  // namespace sp::geo
