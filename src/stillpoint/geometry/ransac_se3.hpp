#pragma once
// Robust rigid alignment of 3-D correspondences (e.g. RGB-D loop-closure candidates): RANSAC over
// minimal 3-point samples (closed form), then a least-squares refit on the consensus set.
#include <Eigen/Core>
#include <cstdint>
#include <optional>
#include <vector>

#include "stillpoint/geometry/lie.hpp"

namespace sp::geo {

struct RansacSe3Config {
  int iterations = 200;            // minimal samples drawn, [1, 100000]
  double inlier_threshold = 0.05;  // metres, ||T src - dst|| below this is an inlier
  int min_inliers = 15;            // fewer inliers => no result
  std::uint32_t seed = 1;          // same seed and input => same result
};

struct RansacSe3Result {
  SE3 T_dst_src;              // dst ≈ T_dst_src * src
  std::vector<bool> inliers;  // per correspondence
  int inlier_count = 0;
};

// Throws sp::Error when src and dst differ in size; nullopt when fewer than 3 pairs are given or
// the best consensus set has fewer than min_inliers. Degenerate (near-collinear) samples are skipped.
std::optional<RansacSe3Result> estimate_se3_ransac(const std::vector<Eigen::Vector3d>& src,
                                                   const std::vector<Eigen::Vector3d>& dst,
                                                   const RansacSe3Config& config);

}  // namespace sp::geo
