#include "stillpoint/tracking/projection_matcher.hpp"

#include <cmath>

#include "stillpoint/features/descriptor.hpp"
#include "stillpoint/features/matching.hpp"

namespace sp::track {

namespace {

int distance(const cv::Mat& a, int row_a, const cv::Mat& b, int row_b) {
  return feat::hamming_distance(a.ptr<std::uint8_t>(row_a), b.ptr<std::uint8_t>(row_b));
}

// Removes matches whose orientation change disagrees with the dominant rotation.
void apply_rotation_check(Frame& cur, feat::RotationHistogram& hist, int& matches) {
  for (std::size_t idx : hist.outliers()) {
    if (cur.points[idx] != map::kNoPoint) {
      cur.points[idx] = map::kNoPoint;
      --matches;
    }
  }
}

// The virtual right coordinate must agree too: it checks the depth (RGB-D).
bool right_coordinate_agrees(const Frame& cur, std::size_t ci, double u, double z, double bf, double radius) {
  return cur.features.u_right[ci] <= 0 || std::abs(u - bf / z - cur.features.u_right[ci]) <= radius;
}

float angle_diff(float a, float b) {
  float d = a - b;
  if (d < 0) d += 360.0f;
  return d;
}

}  // namespace

bool project_point(const geo::SE3& T_cw, const Eigen::Vector3d& p_w, const geo::CameraIntrinsics& camera,
                   Eigen::Vector2d& uv, double& depth) {
  const Eigen::Vector3d p_c = T_cw * p_w;
  depth = p_c.z();
  if (depth <= 0) return false;
  uv = camera.project(p_c);
  return camera.in_image(uv);
}

int match_last_frame(const LocalMapSnapshot& map, Frame& cur, const Frame& last, double radius,
                     const MatchContext& ctx) {
  int matches = 0;
  feat::RotationHistogram hist;
  const Eigen::Vector3d t_cl = (cur.T_cw * last.T_cw.inverse()).translation();
  // Forward/backward camera motion shifts the expected pyramid level (ORB-SLAM's monocular/RGB-D trick).
  const bool forward = t_cl.z() > 0.05;
  const bool backward = t_cl.z() < -0.05;
  std::vector<std::size_t> candidates;  // reused: one allocation per call, not per point
  for (std::size_t i = 0; i < last.points.size(); ++i) {
    if (last.points[i] == map::kNoPoint || last.outlier[i]) continue;
    const LocalMapSnapshot::Point* p = map.live_point(last.points[i]);
    if (p == nullptr) continue;
    Eigen::Vector2d uv;
    double z = 0;
    if (!project_point(cur.T_cw, p->position, ctx.camera, uv, z)) continue;
    const int last_level = last.features.keypoints[i].octave;
    const double r = radius * ctx.pyramid.scale[static_cast<std::size_t>(last_level)];
    if (forward) {
      cur.grid.in_area(uv.x(), uv.y(), static_cast<float>(r), candidates, last_level);
    } else if (backward) {
      cur.grid.in_area(uv.x(), uv.y(), static_cast<float>(r), candidates, 0, last_level);
    } else {
      cur.grid.in_area(uv.x(), uv.y(), static_cast<float>(r), candidates, last_level - 1, last_level + 1);
    }
    int best = 256;
    int best_idx = -1;
    for (const std::size_t ci : candidates) {
      const int c = static_cast<int>(ci);
      if (cur.points[ci] != map::kNoPoint || !right_coordinate_agrees(cur, ci, uv.x(), z, ctx.bf, r))
        continue;
      const int d =
          feat::hamming_distance(p->descriptor.data(), cur.features.descriptors.ptr<std::uint8_t>(c));
      if (d < best) {
        best = d;
        best_idx = c;
      }
    }
    if (best_idx >= 0 && best <= kDescriptorThHigh) {
      cur.points[static_cast<std::size_t>(best_idx)] = p->id;
      ++matches;
      hist.add(angle_diff(last.features.keypoints[i].angle,
                          cur.features.keypoints[static_cast<std::size_t>(best_idx)].angle),
               static_cast<std::size_t>(best_idx));
    }
  }
  apply_rotation_check(cur, hist, matches);
  return matches;
}

int match_local_points(const LocalMapSnapshot& map, Frame& cur, const std::vector<map::PointId>& local_points,
                       double radius_factor, const MatchContext& ctx, PointCounterUpdates& counters) {
  int matches = 0;
  const Eigen::Vector3d center = cur.camera_center();
  std::vector<std::size_t> candidates;  // reused across points
  for (std::size_t k = 0; k < local_points.size(); ++k) {
    const LocalMapSnapshot::Point* p = map.live_point(local_points[k]);
    // A point replaced by another was bad when copied: skipped, not followed (its slot moved on).
    if (p == nullptr || p->id != local_points[k]) continue;
    Eigen::Vector2d uv;
    double z = 0;
    if (!project_point(cur.T_cw, p->position, ctx.camera, uv, z)) continue;
    const Eigen::Vector3d ray = p->position - center;
    const double dist = ray.norm();
    if (dist < 0.8 * p->min_distance || dist > 1.2 * p->max_distance) continue;
    if (ray.dot(p->normal) / dist < 0.5) continue;  // viewing angle over 60 deg
    counters.visible(p->id);
    const int level = p->predict_level(dist, ctx.pyramid);
    // Wider window when the viewing direction is close to the mean one (ORB-SLAM's heuristic).
    const double cos_view = ray.dot(p->normal) / dist;
    const double r =
        radius_factor * (cos_view > 0.998 ? 2.5 : 4.0) * ctx.pyramid.scale[static_cast<std::size_t>(level)];
    cur.grid.in_area(uv.x(), uv.y(), static_cast<float>(r), candidates, level - 1, level);
    int best = 256, second = 256, best_level = -1, second_level = -1, best_idx = -1;
    for (const std::size_t ci : candidates) {
      const int c = static_cast<int>(ci);
      if (cur.points[ci] != map::kNoPoint || !right_coordinate_agrees(cur, ci, uv.x(), z, ctx.bf, r))
        continue;
      const int d =
          feat::hamming_distance(p->descriptor.data(), cur.features.descriptors.ptr<std::uint8_t>(c));
      if (d < best) {
        second = best;
        second_level = best_level;
        best = d;
        best_level = cur.features.keypoints[ci].octave;
        best_idx = c;
      } else if (d < second) {
        second = d;
        second_level = cur.features.keypoints[ci].octave;
      }
    }
    if (best_idx < 0 || best > kDescriptorThHigh) continue;
    // Ratio test only between candidates of the same level (ORB-SLAM).
    if (best_level == second_level && best > 0.8 * second) continue;
    cur.points[static_cast<std::size_t>(best_idx)] = p->id;
    ++matches;
  }
  return matches;
}

int match_local_points(map::MapView& view, Frame& cur, const std::vector<map::PointId>& local_points,
                       double radius_factor, const MatchContext& ctx) {
  LocalMapSnapshot map;
  map.reset({});
  for (map::PointId pid : local_points) map.add(view, pid);
  PointCounterUpdates counters;
  const int matches = match_local_points(map, cur, local_points, radius_factor, ctx, counters);
  counters.apply(view);
  return matches;
}

int match_keyframe(const LocalMapSnapshot::Keyframe& kf, Frame& cur, float ratio) {
  int matches = 0;
  feat::RotationHistogram hist;
  std::vector<int> best_for_cur(cur.features.size(), 256);
  for (std::size_t i = 0; i < kf.points.size(); ++i) {
    if (kf.points[i] == map::kNoPoint) continue;  // the live point's id
    int best = 256, second = 256, best_idx = -1;
    for (std::size_t c = 0; c < cur.features.size(); ++c) {
      const int d =
          distance(kf.descriptors, static_cast<int>(i), cur.features.descriptors, static_cast<int>(c));
      if (d < best) {
        second = best;
        best = d;
        best_idx = static_cast<int>(c);
      } else if (d < second) {
        second = d;
      }
    }
    if (best_idx < 0 || best > kDescriptorThLow || best > ratio * second) continue;
    const auto bi = static_cast<std::size_t>(best_idx);
    if (cur.points[bi] != map::kNoPoint && best >= best_for_cur[bi]) continue;
    if (cur.points[bi] == map::kNoPoint) ++matches;
    cur.points[bi] = kf.points[i];
    best_for_cur[bi] = best;
    hist.add(angle_diff(kf.angles[i], cur.features.keypoints[bi].angle), bi);
  }
  apply_rotation_check(cur, hist, matches);
  return matches;
}

int fuse_into_keyframe(map::MapView& view, map::KeyframeId target, const std::vector<map::PointId>& points,
                       double radius, const MatchContext& ctx) {
  map::Keyframe* kf = view.keyframe(target);
  if (kf == nullptr || kf->bad) return 0;
  const Eigen::Vector3d center = kf->camera_center();
  int fused = 0;
  for (map::PointId pid : points) {
    map::MapPoint* p = view.live_point(pid);
    if (p == nullptr || p->observations.contains(target)) continue;
    Eigen::Vector2d uv;
    double z = 0;
    if (!project_point(kf->T_cw, p->position, ctx.camera, uv, z)) continue;
    const Eigen::Vector3d ray = p->position - center;
    const double dist = ray.norm();
    if (dist < 0.8 * p->min_distance || dist > 1.2 * p->max_distance) continue;
    if (ray.dot(p->normal) / dist < 0.5) continue;
    const int level = p->predict_level(dist, ctx.pyramid);
    const double r = radius * ctx.pyramid.scale[static_cast<std::size_t>(level)];
    int best = 256, best_idx = -1;
    for (const std::size_t ci : kf->index.in_area(uv.x(), uv.y(), static_cast<float>(r))) {
      const int c = static_cast<int>(ci);
      const auto& kp = kf->features.keypoints[ci];
      if (kp.octave < level - 1 || kp.octave > level) continue;
      // Reprojection error gate (chi-square 3 dof for RGB-D, 2 dof otherwise).
      const double inv_s2 = ctx.pyramid.inv_level_sigma2[static_cast<std::size_t>(kp.octave)];
      const double eu = uv.x() - kp.pt.x, ev = uv.y() - kp.pt.y;
      double e2 = (eu * eu + ev * ev) * inv_s2;
      const float ur = kf->features.u_right[ci];
      if (ur > 0) {
        const double er = uv.x() - ctx.bf / z - ur;
        if ((e2 + er * er * inv_s2) > 7.8) continue;
      } else if (e2 > 5.99) {
        continue;
      }
      const int d = feat::hamming_distance(p->descriptor.ptr<std::uint8_t>(),
                                           kf->features.descriptors.ptr<std::uint8_t>(c));
      if (d < best) {
        best = d;
        best_idx = c;
      }
    }
    if (best_idx < 0 || best > 50) continue;
    const map::PointId existing = kf->points[static_cast<std::size_t>(best_idx)];
    const map::MapPoint* other = existing == map::kNoPoint ? nullptr : view.live_point(existing);
    if (other != nullptr) {
      // Keep the better-observed point.
      if (other->observations.size() >= p->observations.size()) {
        view.replace_point(p->id, other->id);
      } else {
        view.replace_point(other->id, p->id);
      }
    } else {
      view.add_observation(p->id, target, best_idx);
    }
    ++fused;
  }
  return fused;
}

}  // namespace sp::track
