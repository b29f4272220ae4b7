#include "stillpoint/geometry/ransac_se3.hpp"

#include <random>

#include "stillpoint/common/error.hpp"
#include "stillpoint/geometry/alignment.hpp"

namespace sp::geo {
namespace {

// Counts (and optionally marks) correspondences within the threshold.
int count_inliers(const SE3& T, const std::vector<Eigen::Vector3d>& src,
                  const std::vector<Eigen::Vector3d>& dst, double threshold2, std::vector<bool>* mask) {
  int count = 0;
  for (std::size_t i = 0; i < src.size(); ++i) {
    const bool in = (T * src[i] - dst[i]).squaredNorm() < threshold2;
    if (mask != nullptr) (*mask)[i] = in;
    count += in ? 1 : 0;
  }
  return count;
}

SE3 fit(const std::vector<Eigen::Vector3d>& src, const std::vector<Eigen::Vector3d>& dst) {
  const Similarity3 s = align_umeyama(src, dst, false);
  return SE3(s.R, s.t);
}

}  // namespace

std::optional<RansacSe3Result> estimate_se3_ransac(const std::vector<Eigen::Vector3d>& src,
                                                   const std::vector<Eigen::Vector3d>& dst,
                                                   const RansacSe3Config& config) {
  if (src.size() != dst.size()) throw Error("estimate_se3_ransac: src and dst differ in size");
  const std::size_t n = src.size();
  if (n < 3) return std::nullopt;
  const double threshold2 = config.inlier_threshold * config.inlier_threshold;
  // mt19937 is fully specified by the standard; the modulo draw (unlike the std distributions) is
  // too, so a seed gives the same samples with every standard library.
  std::mt19937 rng(config.seed);
  const auto draw = [&] { return static_cast<std::size_t>(rng() % n); };

  int best_count = -1;
  SE3 best;
  std::vector<Eigen::Vector3d> s3(3), d3(3);
  for (int it = 0; it < config.iterations; ++it) {
    const std::size_t a = draw();
    std::size_t b = draw(), c = draw();
    if (a == b || a == c || b == c) continue;
    // Skip near-collinear samples: their rotation about the common line is undetermined.
    const double area = (src[b] - src[a]).cross(src[c] - src[a]).norm();
    const double span = (src[b] - src[a]).squaredNorm() + (src[c] - src[a]).squaredNorm();
    if (area < 1e-3 * span || area < 1e-12) continue;
    s3 = {src[a], src[b], src[c]};
    d3 = {dst[a], dst[b], dst[c]};
    const SE3 T = fit(s3, d3);
    const int count = count_inliers(T, src, dst, threshold2, nullptr);
    if (count > best_count) {
      best_count = count;
      best = T;
    }
  }
  if (best_count < std::max(config.min_inliers, 3)) return std::nullopt;

  RansacSe3Result result;
  result.inliers.assign(n, false);
  result.T_dst_src = best;
  result.inlier_count = count_inliers(best, src, dst, threshold2, &result.inliers);
  // Refit on the consensus set until it stops changing (a few rounds at most).
  for (int round = 0; round < 3; ++round) {
    std::vector<Eigen::Vector3d> si, di;
    for (std::size_t i = 0; i < n; ++i) {
      if (!result.inliers[i]) continue;
      si.push_back(src[i]);
      di.push_back(dst[i]);
    }
    const SE3 T = fit(si, di);
    std::vector<bool> mask(n, false);
    const int count = count_inliers(T, src, dst, threshold2, &mask);
    if (count < result.inlier_count) break;  // the refit must not lose support
    const bool same = mask == result.inliers;
    result.T_dst_src = T;
    result.inliers = std::move(mask);
    result.inlier_count = count;
    if (same) break;
  }
  if (result.inlier_count < config.min_inliers) return std::nullopt;
  return result;
}

}  // namespace sp::geo
