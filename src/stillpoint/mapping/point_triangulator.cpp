#include "stillpoint/mapping/point_triangulator.hpp"

#include <Eigen/SVD>
#include <algorithm>
#include <array>
#include <cmath>

#include "stillpoint/features/descriptor.hpp"

namespace sp::mapping {
namespace {

constexpr int kRotationBins = 30;

Eigen::Matrix<double, 3, 4> projection(const geo::SE3& T_cw) {
  Eigen::Matrix<double, 3, 4> P;
  P.leftCols<3>() = T_cw.rotation();
  P.col(3) = T_cw.translation();
  return P;
}

// Linear (DLT) triangulation from normalised image coordinates; false at infinity.
bool triangulate_linear(const Eigen::Vector2d& n1, const Eigen::Matrix<double, 3, 4>& P1,
                        const Eigen::Vector2d& n2, const Eigen::Matrix<double, 3, 4>& P2,
                        Eigen::Vector3d& p_w) {
  Eigen::Matrix4d A;
  A.row(0) = n1.x() * P1.row(2) - P1.row(0);
  A.row(1) = n1.y() * P1.row(2) - P1.row(1);
  A.row(2) = n2.x() * P2.row(2) - P2.row(0);
  A.row(3) = n2.y() * P2.row(2) - P2.row(1);
  const Eigen::JacobiSVD<Eigen::Matrix4d> svd(A, Eigen::ComputeFullV);
  const Eigen::Vector4d h = svd.matrixV().col(3);
  if (std::abs(h(3)) < 1e-12) return false;
  p_w = h.head<3>() / h(3);
  return p_w.allFinite();
}

// The three most populated rotation bins (the second and third only when they hold at least a tenth
// of the first): matches whose orientation change disagrees with the image's dominant one are wrong.
std::array<int, 3> three_largest(const std::array<int, kRotationBins>& counts) {
  std::array<int, 3> idx{-1, -1, -1};
  std::array<int, 3> val{0, 0, 0};
  for (int b = 0; b < kRotationBins; ++b) {
    const int c = counts[static_cast<std::size_t>(b)];
    if (c > val[0]) {
      val = {c, val[0], val[1]};
      idx = {b, idx[0], idx[1]};
    } else if (c > val[1]) {
      val = {val[0], c, val[1]};
      idx = {idx[0], b, idx[1]};
    } else if (c > val[2]) {
      val[2] = c;
      idx[2] = b;
    }
  }
  if (val[1] < 0.1 * val[0])
    idx[1] = idx[2] = -1;
  else if (val[2] < 0.1 * val[0])
    idx[2] = -1;
  return idx;
}

}  // namespace

TriangulationConfig TriangulationConfig::from_yaml(const ConfigReader& r) {
  TriangulationConfig c;
  r.read("enabled", c.enabled);
  r.read("neighbours", c.neighbours, std::size_t{1}, std::size_t{100});
  r.read("max_descriptor_distance", c.max_descriptor_distance, 1, 256);
  r.read("min_parallax_cos", c.min_parallax_cos, 0.9, 1.0);
  r.read("mono_match_ratio", c.mono_match_ratio, 0.1, 1.0);
  return c;
}

PointTriangulator::PointTriangulator(TriangulationConfig config, geo::CameraIntrinsics camera, double bf,
                                     map::ScalePyramid pyramid)
    : config_(config), camera_(camera), bf_(bf), pyramid_(std::move(pyramid)) {}

std::vector<PointTriangulator::Match> PointTriangulator::match_epipolar(const TriangulationView& v1,
                                                                        const TriangulationView& v2) const {
  const map::FeatureSet& f1 = *v1.features;
  const map::FeatureSet& f2 = *v2.features;
  // F21 maps a pixel of view 1 to its epipolar line in view 2: x2^T F21 x1 = 0.
  const geo::SE3 T21 = v2.T_cw * v1.T_cw.inverse();
  const Eigen::Matrix3d R21 = T21.rotation();
  const Eigen::Vector3d& t21 = T21.translation();
  Eigen::Matrix3d tx;
  tx << 0, -t21.z(), t21.y(), t21.z(), 0, -t21.x(), -t21.y(), t21.x(), 0;
  Eigen::Matrix3d K;
  K << camera_.fx, 0, camera_.cx, 0, camera_.fy, camera_.cy, 0, 0, 1;
  const Eigen::Matrix3d K_inv = K.inverse();
  const Eigen::Matrix3d F21 = K_inv.transpose() * tx * R21 * K_inv;
  // Epipole in view 2: where view 1's centre projects.
  const Eigen::Vector3d c1_in_2 = T21.translation();
  const bool epipole_in_front = c1_in_2.z() > 0;
  const Eigen::Vector2d epipole = epipole_in_front ? camera_.project(c1_in_2) : Eigen::Vector2d::Zero();

  std::vector<int> free2;
  for (std::size_t j = 0; j < f2.size(); ++j) {
    if (v2.free[j]) free2.push_back(static_cast<int>(j));
  }
  std::vector<Match> best_for_2(f2.size(), Match{-1, -1, 256});
  for (std::size_t i = 0; i < f1.size(); ++i) {
    if (!v1.free[i]) continue;
    const cv::KeyPoint& kp1 = f1.keypoints[i];
    const Eigen::Vector3d line = F21 * Eigen::Vector3d(kp1.pt.x, kp1.pt.y, 1.0);
    const double norm2 = line.x() * line.x() + line.y() * line.y();
    if (norm2 <= 0) continue;
    const bool depth1 = f1.depth[i] > 0;
    const std::uint8_t* d1 = f1.descriptors.ptr<std::uint8_t>(static_cast<int>(i));
    int best = config_.max_descriptor_distance + 1, best_j = -1;
    // The runner-up: the second-best distance in the band, or the distance limit when that is lower.
    int second = 256;
    for (int j : free2) {
      const cv::KeyPoint& kp2 = f2.keypoints[static_cast<std::size_t>(j)];
      const auto level2 = static_cast<std::size_t>(kp2.octave);
      const double num = line.x() * kp2.pt.x + line.y() * kp2.pt.y + line.z();
      // 1 px at level 0, 3.84 = chi-square 1 dof at 95 %.
      if (num * num / norm2 > 3.84 / pyramid_.inv_level_sigma2[level2]) continue;
      const bool depth2 = f2.depth[static_cast<std::size_t>(j)] > 0;
      if (!depth1 && !depth2 && epipole_in_front) {
        // Near the epipole a monocular match says nothing about depth.
        const double ex = epipole.x() - kp2.pt.x, ey = epipole.y() - kp2.pt.y;
        if (ex * ex + ey * ey < 100.0 * pyramid_.scale[level2]) continue;
      }
      const int d = feat::hamming_distance(d1, f2.descriptors.ptr<std::uint8_t>(j));
      if (d < best) {
        second = best;
        best = d;
        best_j = j;
      } else if (d < second) {
        second = d;
      }
    }
    if (best_j < 0) continue;
    // Repeated texture (book spines, tiles) beyond the depth sensor's range: without depth in either
    // view the best match must stand out from the runner-up along the line (and be well under the limit).
    if (!depth1 && f2.depth[static_cast<std::size_t>(best_j)] <= 0 &&
        static_cast<double>(best) > config_.mono_match_ratio * static_cast<double>(second))
      continue;
    Match& slot = best_for_2[static_cast<std::size_t>(best_j)];
    if (best < slot.distance) slot = Match{static_cast<int>(i), best_j, best};
  }

  std::vector<Match> matches;
  std::array<int, kRotationBins> counts{};
  std::vector<int> bin_of;
  for (const Match& m : best_for_2) {
    if (m.i1 < 0) continue;
    double rot = f1.keypoints[static_cast<std::size_t>(m.i1)].angle -
                 f2.keypoints[static_cast<std::size_t>(m.i2)].angle;
    if (rot < 0) rot += 360.0;
    const int bin = static_cast<int>(std::lround(rot * kRotationBins / 360.0)) % kRotationBins;
    ++counts[static_cast<std::size_t>(bin)];
    bin_of.push_back(bin);
    matches.push_back(m);
  }
  const std::array<int, 3> keep = three_largest(counts);
  std::vector<Match> consistent;
  for (std::size_t k = 0; k < matches.size(); ++k) {
    if (bin_of[k] == keep[0] || bin_of[k] == keep[1] || bin_of[k] == keep[2])
      consistent.push_back(matches[k]);
  }
  return consistent;
}

bool PointTriangulator::reprojects(const geo::SE3& T_cw, const map::FeatureSet& f, int i,
                                   const Eigen::Vector3d& p_w, double* distance) const {
  const Eigen::Vector3d p_c = T_cw * p_w;
  if (p_c.z() <= 0) return false;
  const auto idx = static_cast<std::size_t>(i);
  const cv::KeyPoint& kp = f.keypoints[idx];
  const double inv_s2 = pyramid_.inv_level_sigma2[static_cast<std::size_t>(kp.octave)];
  const Eigen::Vector2d uv = camera_.project(p_c);
  double e2 = (uv - Eigen::Vector2d(kp.pt.x, kp.pt.y)).squaredNorm();
  const float ur = f.u_right[idx];
  double threshold = 5.991;  // chi-square 2 dof at 95 %
  if (ur >= 0) {
    const double er = uv.x() - bf_ / p_c.z() - ur;
    e2 += er * er;
    threshold = 7.8;  // 3 dof
  }
  if (e2 * inv_s2 > threshold) return false;
  *distance = (p_w - T_cw.inverse().translation()).norm();
  return true;
}

std::vector<TriangulatedPoint> PointTriangulator::triangulate(const TriangulationView& v1,
                                                              const TriangulationView& v2) const {
  std::vector<TriangulatedPoint> out;
  if (v1.features == nullptr || v2.features == nullptr) return out;
  const Eigen::Vector3d c1 = v1.T_cw.inverse().translation();
  const Eigen::Vector3d c2 = v2.T_cw.inverse().translation();
  const double baseline = bf_ / camera_.fx;
  // With less motion than the sensor's own virtual baseline, depth already says all two views could.
  if ((c2 - c1).norm() < baseline) return out;

  const map::FeatureSet& f1 = *v1.features;
  const map::FeatureSet& f2 = *v2.features;
  const Eigen::Matrix3d R1_wc = v1.T_cw.rotation().transpose();
  const Eigen::Matrix3d R2_wc = v2.T_cw.rotation().transpose();
  const Eigen::Matrix<double, 3, 4> P1 = projection(v1.T_cw);
  const Eigen::Matrix<double, 3, 4> P2 = projection(v2.T_cw);
  const double ratio_factor = 1.5 * pyramid_.scale_factor;

  for (const Match& m : match_epipolar(v1, v2)) {
    const auto i1 = static_cast<std::size_t>(m.i1);
    const auto i2 = static_cast<std::size_t>(m.i2);
    const cv::KeyPoint& kp1 = f1.keypoints[i1];
    const cv::KeyPoint& kp2 = f2.keypoints[i2];
    const Eigen::Vector2d n1((kp1.pt.x - camera_.cx) / camera_.fx, (kp1.pt.y - camera_.cy) / camera_.fy);
    const Eigen::Vector2d n2((kp2.pt.x - camera_.cx) / camera_.fx, (kp2.pt.y - camera_.cy) / camera_.fy);
    const Eigen::Vector3d ray1 = R1_wc * Eigen::Vector3d(n1.x(), n1.y(), 1.0);
    const Eigen::Vector3d ray2 = R2_wc * Eigen::Vector3d(n2.x(), n2.y(), 1.0);
    const double cos_rays = ray1.dot(ray2) / (ray1.norm() * ray2.norm());
    // The parallax a depth reading stands for: the virtual stereo pair's angle at that depth.
    const float z1 = f1.depth[i1], z2 = f2.depth[i2];
    const double cos_depth1 = z1 > 0 ? std::cos(2.0 * std::atan2(baseline / 2.0, z1)) : 2.0;
    const double cos_depth2 = z2 > 0 ? std::cos(2.0 * std::atan2(baseline / 2.0, z2)) : 2.0;
    const double cos_depth = std::min(cos_depth1, cos_depth2);

    Eigen::Vector3d p_w;
    if (cos_rays < cos_depth && cos_rays > 0 && (z1 > 0 || z2 > 0 || cos_rays < config_.min_parallax_cos)) {
      if (!triangulate_linear(n1, P1, n2, P2, p_w)) continue;
    } else if (z1 > 0 && cos_depth1 < cos_depth2) {
      p_w = v1.T_cw.inverse() * camera_.unproject({kp1.pt.x, kp1.pt.y}, z1);
    } else if (z2 > 0 && cos_depth2 < cos_depth1) {
      p_w = v2.T_cw.inverse() * camera_.unproject({kp2.pt.x, kp2.pt.y}, z2);
    } else {
      continue;  // too little parallax and no depth
    }
    double dist1 = 0, dist2 = 0;
    if (!reprojects(v1.T_cw, f1, m.i1, p_w, &dist1) || !reprojects(v2.T_cw, f2, m.i2, p_w, &dist2)) continue;
    if (dist1 <= 0 || dist2 <= 0) continue;
    // Scale consistency: the distance ratio must agree with the pyramid levels the corner was found at.
    const double ratio_dist = dist2 / dist1;
    const double ratio_octave = pyramid_.scale[static_cast<std::size_t>(kp1.octave)] /
                                pyramid_.scale[static_cast<std::size_t>(kp2.octave)];
    if (ratio_dist * ratio_factor < ratio_octave || ratio_dist > ratio_octave * ratio_factor) continue;
    out.push_back({p_w, m.i1, m.i2});
  }
  return out;
}

}  // namespace sp::mapping
