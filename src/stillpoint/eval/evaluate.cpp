#include "stillpoint/eval/evaluate.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "stillpoint/common/error.hpp"
#include "stillpoint/io/association.hpp"

namespace sp::eval {

namespace {

std::vector<io::StampedPose> sorted_by_stamp(std::vector<io::StampedPose> poses) {
  std::stable_sort(poses.begin(), poses.end(),
                   [](const io::StampedPose& a, const io::StampedPose& b) { return a.stamp < b.stamp; });
  return poses;
}

// evaluate_rpe.py's find_closest_index: a binary search that remembers the closest value it visited.
// Kept step for step (strict '<', first index wins) so ties resolve as in the reference.
std::size_t find_closest_index(const std::vector<double>& values, double t) {
  std::size_t begin = 0, end = values.size(), best = 0;
  double difference = std::abs(values[0] - t);
  while (begin < end) {
    const std::size_t middle = (begin + end) / 2;
    if (std::abs(values[middle] - t) < difference) {
      difference = std::abs(values[middle] - t);
      best = middle;
    }
    if (t == values[middle]) return middle;
    if (values[middle] > t) {
      end = middle;
    } else {
      begin = middle + 1;
    }
  }
  return best;
}

Eigen::Isometry3d to_isometry(const io::StampedPose& p) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = p.q.normalized().toRotationMatrix();
  T.translation() = p.t;
  return T;
}

double median_interval(const std::vector<double>& stamps) {
  std::vector<double> d;
  for (std::size_t k = 1; k < stamps.size(); ++k) d.push_back(stamps[k] - stamps[k - 1]);
  return compute_stats(std::move(d)).median;
}

void evaluate_ate(const std::vector<io::StampedPose>& gt, const std::vector<io::StampedPose>& est,
                  const EvalOptions& o, EvalResult& r) {
  std::vector<double> gt_stamps, est_stamps;
  for (const auto& p : gt) gt_stamps.push_back(p.stamp);
  for (const auto& p : est) est_stamps.push_back(p.stamp);
  // evaluate_ate.py associates (first = ground truth, second = estimate): |t_gt - (t_est + offset)|.
  const auto matches = io::associate(gt_stamps, est_stamps, o.offset, o.max_difference);
  const std::size_t need = o.align == Alignment::None ? 1 : 3;
  if (matches.size() < need) {
    throw Error(
        fmt::format("evaluate: the trajectories do not overlap in time ({} associated poses within "
                    "{:g} s, need {})",
                    matches.size(), o.max_difference, need));
  }
  std::vector<Eigen::Vector3d> src, dst;
  for (const auto& [i, j] : matches) {
    dst.push_back(gt[i].t);
    src.push_back(est[j].t);
    r.stamps.push_back(est[j].stamp);
  }
  if (o.align != Alignment::None) r.alignment = geo::align_umeyama(src, dst, o.align == Alignment::Sim3);
  r.pairs = matches.size();
  r.gt_positions = dst;
  Eigen::Vector3d camera_axes_sq = Eigen::Vector3d::Zero();
  for (std::size_t k = 0; k < src.size(); ++k) {
    r.est_positions.push_back(r.alignment.apply(src[k]));
    const Eigen::Vector3d error_w = r.est_positions.back() - dst[k];
    r.ate_errors.push_back(error_w.norm());
    // TUM poses are camera-to-world, so R_wc^T takes a world vector into the camera's frame.
    const Eigen::Vector3d error_c = gt[matches[k].first].q.normalized().conjugate() * error_w;
    camera_axes_sq += error_c.cwiseAbs2();
  }
  r.ate_camera_axes_rmse = (camera_axes_sq / static_cast<double>(src.size())).cwiseSqrt();
  r.ate = compute_stats(r.ate_errors);
}

void evaluate_rpe(const std::vector<io::StampedPose>& gt, const std::vector<io::StampedPose>& est,
                  const EvalOptions& o, EvalResult& r) {
  if (gt.size() < 2 || est.size() < 2) return;
  std::vector<double> gt_stamps, est_stamps, index;
  for (const auto& p : gt) gt_stamps.push_back(p.stamp);
  for (const auto& p : est) est_stamps.push_back(p.stamp);
  if (o.delta_unit == DeltaUnit::Seconds) {
    index = est_stamps;
  } else {
    for (std::size_t k = 0; k < est.size(); ++k) index.push_back(static_cast<double>(k));
  }
  const double max_gap = 2.0 * median_interval(gt_stamps);
  for (std::size_t i = 0; i < est.size(); ++i) {
    const std::size_t j = find_closest_index(index, index[i] + o.delta);
    if (j == est.size() - 1) continue;  // as the reference: the last estimate never ends a pair
    const std::size_t g0 = find_closest_index(gt_stamps, est_stamps[i] + o.offset);
    const std::size_t g1 = find_closest_index(gt_stamps, est_stamps[j] + o.offset);
    if (std::abs(gt_stamps[g0] - (est_stamps[i] + o.offset)) > max_gap ||
        std::abs(gt_stamps[g1] - (est_stamps[j] + o.offset)) > max_gap) {
      continue;
    }
    // E = (P_i^-1 P_j) (Q_i^-1 Q_j)^-1, P estimate, Q ground truth.
    Eigen::Isometry3d d_est = to_isometry(est[i]).inverse() * to_isometry(est[j]);
    d_est.translation() *= r.alignment.scale;  // evaluate_rpe.py --scale: 1 unless aligned with Sim(3)
    const Eigen::Isometry3d d_gt = to_isometry(gt[g0]).inverse() * to_isometry(gt[g1]);
    const Eigen::Isometry3d E = d_est * d_gt.inverse();
    const double c = std::clamp((E.linear().trace() - 1.0) / 2.0, -1.0, 1.0);
    r.rpe_stamps.push_back(est_stamps[i]);
    r.rpe_trans_errors.push_back(E.translation().norm());
    r.rpe_rot_errors_deg.push_back(std::acos(c) * 180.0 / M_PI);
  }
  r.rpe_pairs = r.rpe_trans_errors.size();
  r.rpe_trans = compute_stats(r.rpe_trans_errors);
  r.rpe_rot_deg = compute_stats(r.rpe_rot_errors_deg);
}

}  // namespace

EvalOptions EvalOptions::from_yaml(const ConfigReader& r) {
  EvalOptions o;
  std::string align = "se3", unit = "s";
  r.read_choice("align", align, {"se3", "sim3", "none"});
  o.align = align == "sim3" ? Alignment::Sim3 : align == "none" ? Alignment::None : Alignment::SE3;
  r.read("delta", o.delta, 1e-9, 1e6);
  r.read_choice("delta_unit", unit, {"s", "f"});
  o.delta_unit = unit == "f" ? DeltaUnit::Frames : DeltaUnit::Seconds;
  r.read("max_difference", o.max_difference, 1e-6, 10.0);
  r.read("offset", o.offset, -1e4, 1e4);
  return o;
}

EvalResult evaluate(const std::vector<io::StampedPose>& gt_in, const std::vector<io::StampedPose>& est_in,
                    const EvalOptions& options) {
  if (!(options.delta > 0)) throw Error("evaluate: delta must be positive");
  if (!(options.max_difference > 0)) throw Error("evaluate: max_difference must be positive");
  if (gt_in.empty() || est_in.empty()) throw Error("evaluate: empty trajectory, nothing to compare");
  const auto gt = sorted_by_stamp(gt_in);
  const auto est = sorted_by_stamp(est_in);
  EvalResult r;
  evaluate_ate(gt, est, options, r);
  evaluate_rpe(gt, est, options, r);
  if (r.rpe_pairs == 0) spdlog::warn("evaluate: no relative pose pair fits delta {}", options.delta);
  return r;
}

}  // namespace sp::eval
