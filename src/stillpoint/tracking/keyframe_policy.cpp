#include "stillpoint/tracking/keyframe_policy.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>

#include "stillpoint/common/error.hpp"

namespace sp::track {

KeyframePolicyConfig KeyframePolicyConfig::from_yaml(const ConfigReader& r) {
  KeyframePolicyConfig c;
  r.read_choice("policy", c.policy, {"heuristic", "adaptive"});
  r.read("max_interval_s", c.max_interval_s, 0.05, 60.0);
  r.read("min_interval_s", c.min_interval_s, 0.0, 60.0);
  r.read("reference_ratio", c.reference_ratio, 0.05, 1.0);
  r.read("min_inliers", c.min_inliers, 0, 1000);
  r.read("close_tracked_min", c.close_tracked_min, 0, 10000);
  r.read("close_untracked_min", c.close_untracked_min, 0, 10000);
  r.read("max_mapping_queue", c.max_mapping_queue, std::size_t{1}, std::size_t{100});
  r.read("effective_angle_deg", c.effective_angle_deg, 1.0, 90.0);
  r.read_choice("effective_reference", c.effective_reference, {"keyframe", "point"});
  r.read("effective_share", c.effective_share, 0.0, 1.0);
  r.read("effective_min", c.effective_min, 0, 10000);
  r.read("hold_min_tracked", c.hold_min_tracked, 0, 100000);
  r.read("hold_max_translation_m", c.hold_max_translation_m, 0.0, 1.0);
  r.read("hold_max_rotation_deg", c.hold_max_rotation_deg, 0.0, 45.0);
  return c;
}

namespace {

// Conditions both policies share: never from a weak frame, never when mapping is swamped, and a
// keyframe when tracking is about to run out of close points or of reference points.
struct SafetyNets {
  bool weak = false;
  bool swamped = false;
  bool at_reference = false;
  bool need_close = false;
  bool losing_reference = false;
  bool timed_out = false;
};

SafetyNets safety_nets(const KeyframePolicyConfig& cfg, const KeyframeCandidate& c) {
  SafetyNets s;
  s.weak = c.tracked_inliers <= cfg.min_inliers;
  s.swamped = !c.mapping_idle && c.mapping_queue >= cfg.max_mapping_queue;
  s.at_reference = cfg.hold_min_tracked > 0 && c.tracked_inliers >= cfg.hold_min_tracked &&
                   c.reference_translation_m <= cfg.hold_max_translation_m &&
                   c.reference_rotation_deg <= cfg.hold_max_rotation_deg;
  s.need_close = c.close_tracked < cfg.close_tracked_min && c.close_untracked > cfg.close_untracked_min;
  const double ratio = c.keyframes_in_map < 2 ? 0.4 : cfg.reference_ratio;
  s.losing_reference = c.tracked_inliers < ratio * c.reference_tracked;
  s.timed_out = static_cast<double>(c.frames_since_keyframe) >= cfg.max_interval_s * c.fps;
  return s;
}

// Per-rule counters; `Names` lists the JSON keys in rule order.
template <std::size_t N>
class RuleCounter {
 public:
  explicit RuleCounter(std::array<const char*, N> names) : names_(names) {}
  void fire(std::size_t rule) const { counts_[rule].fetch_add(1, std::memory_order_relaxed); }
  [[nodiscard]] KeyframeRuleCounts snapshot() const {
    KeyframeRuleCounts out;
    for (std::size_t i = 0; i < N; ++i)
      out.emplace_back(names_[i], counts_[i].load(std::memory_order_relaxed));
    return out;
  }

 private:
  std::array<const char*, N> names_;
  mutable std::array<std::atomic<std::size_t>, N> counts_{};
};

class HeuristicPolicy final : public KeyframePolicy {
 public:
  explicit HeuristicPolicy(KeyframePolicyConfig cfg) : cfg_(std::move(cfg)) {}
  [[nodiscard]] std::string name() const override { return "heuristic"; }
  [[nodiscard]] KeyframeRuleCounts rule_counts() const override { return counter_.snapshot(); }
  [[nodiscard]] bool decide(const KeyframeCandidate& c) const override {
    counter_.fire(kDecisions);
    const SafetyNets s = safety_nets(cfg_, c);
    if (s.weak) counter_.fire(kVetoedWeak);
    if (s.swamped) counter_.fire(kVetoedSwamped);
    if (s.at_reference) counter_.fire(kVetoedAtReference);
    if (s.weak || s.swamped || s.at_reference) return false;
    // ORB-SLAM3 RGB-D: (c1a || c1b || c1c) && c2.
    const bool c1a = s.timed_out;
    const bool c1b =
        c.mapping_idle && static_cast<double>(c.frames_since_keyframe) >= cfg_.min_interval_s * c.fps;
    const bool c1c = c.tracked_inliers < 0.25 * c.reference_tracked || s.need_close;
    const bool c2 = s.losing_reference || s.need_close;
    const bool insert = (c1a || c1b || c1c) && c2;
    if (insert) {
      counter_.fire(kInserted);
      if (c1a) counter_.fire(kTimedOut);
      if (c1b) counter_.fire(kMappingIdle);
      if (c1c) counter_.fire(kWeakOrClose);
    }
    return insert;
  }

 private:
  // The c1 conditions are counted on inserted frames only, and are not exclusive.
  enum Rule : std::size_t {
    kDecisions,
    kVetoedWeak,
    kVetoedSwamped,
    kVetoedAtReference,
    kInserted,
    kTimedOut,
    kMappingIdle,
    kWeakOrClose
  };
  KeyframePolicyConfig cfg_;
  RuleCounter<8> counter_{{"decisions", "vetoed_weak", "vetoed_swamped", "vetoed_at_reference", "inserted",
                           "inserted_timed_out", "inserted_mapping_idle", "inserted_weak_or_close"}};
};

// Paper §III-A. A tracked point is "effective" when its viewing direction changed by more than
// effective_angle_deg since the reference keyframe: the map sees it from a new angle. A keyframe
// candidate needs enough effective points; the threshold follows the observation model: the share
// `effective_share` of the currently tracked inliers (so it scales with how many points the frame
// sees), floored at effective_min. The candidate is accepted when the effective points are spread
// over the image (T2 > T1), so the new keyframe constrains the pose well. The shared safety nets
// still apply (too few tracked points, close points running out, mapping swamped).
class AdaptivePolicy final : public KeyframePolicy {
 public:
  explicit AdaptivePolicy(KeyframePolicyConfig cfg) : cfg_(std::move(cfg)) {}
  [[nodiscard]] std::string name() const override { return "adaptive"; }
  [[nodiscard]] bool needs_view_changes() const override { return true; }
  [[nodiscard]] KeyframeRuleCounts rule_counts() const override { return counter_.snapshot(); }
  [[nodiscard]] bool decide(const KeyframeCandidate& c) const override {
    counter_.fire(kDecisions);
    const SafetyNets s = safety_nets(cfg_, c);
    if (s.weak || s.swamped) {
      counter_.fire(s.weak ? kVetoedWeak : kVetoedSwamped);
      return false;
    }
    if (s.at_reference) {
      counter_.fire(kVetoedAtReference);
      return false;
    }
    if (s.need_close) return inserted(kClosePoints);
    if (c.tracked_inliers < 0.25 * c.reference_tracked) return inserted(kWeakTracking);
    const Eigen::Matrix3i grid =
        effective_point_grid(c.view_changes, c.image_width, c.image_height, cfg_.effective_angle_deg);
    const int effective = grid.sum();
    const double threshold = std::max<double>(cfg_.effective_min, cfg_.effective_share * c.tracked_inliers);
    if (effective > 0) counter_.fire(kAnyEffective);
    if (effective >= threshold) {
      counter_.fire(kThresholdMet);
      if (grid_balance(grid).spread_out()) return inserted(kEffectiveSpread);
      counter_.fire(kNotSpread);
    }
    // Slow drift with no large view change: the reference keyframe is being lost and mapping can take a
    // keyframe (idle, or the maximum interval passed): ORB-SLAM3's coverage rule as the safety net.
    // Requiring both idle AND timed out (our first version) starved the map in walking_xyz, where people
    // hide parts of the reference keyframe without any 30-degree view change.
    if ((c.mapping_idle || s.timed_out) && s.losing_reference) return inserted(kReferenceFallback);
    return false;
  }

 private:
  // Rules in the order decide() tries them; a frame is counted under the rule that decided it.
  // any_effective / threshold_met / threshold_met_not_spread are diagnostics of the paper's rule on the
  // frames that reached it (not decided by a veto or a safety net before).
  enum Rule : std::size_t {
    kDecisions,
    kVetoedWeak,
    kVetoedSwamped,
    kVetoedAtReference,
    kClosePoints,
    kWeakTracking,
    kAnyEffective,
    kThresholdMet,
    kNotSpread,
    kEffectiveSpread,
    kReferenceFallback,
    kInserted,
  };
  bool inserted(Rule rule) const {
    counter_.fire(rule);
    counter_.fire(kInserted);
    return true;
  }
  KeyframePolicyConfig cfg_;
  RuleCounter<12> counter_{{"decisions", "vetoed_weak", "vetoed_swamped", "vetoed_at_reference",
                            "close_points", "weak_tracking", "any_effective", "threshold_met",
                            "threshold_met_not_spread", "effective_spread", "reference_fallback",
                            "inserted"}};
};

}  // namespace

std::unique_ptr<KeyframePolicy> make_keyframe_policy(const KeyframePolicyConfig& config) {
  if (config.policy == "heuristic") return std::make_unique<HeuristicPolicy>(config);
  if (config.policy == "adaptive") return std::make_unique<AdaptivePolicy>(config);
  throw Error("unknown keyframe policy '" + config.policy + "'");
}

double viewing_angle_change_deg(const Eigen::Vector3d& point, const Eigen::Vector3d& center_ref,
                                const Eigen::Vector3d& center_now) {
  const Eigen::Vector3d a = (point - center_ref).normalized();
  const Eigen::Vector3d b = (point - center_now).normalized();
  // atan2 of |a x b| and a.b stays accurate for tiny and near-180 degree angles.
  return std::atan2(a.cross(b).norm(), a.dot(b)) * 180.0 / M_PI;
}

double angle_from_normal_deg(const Eigen::Vector3d& point, const Eigen::Vector3d& normal,
                             const Eigen::Vector3d& center_now) {
  const Eigen::Vector3d b = (point - center_now).normalized();
  return std::atan2(normal.cross(b).norm(), normal.dot(b)) * 180.0 / M_PI;
}

Eigen::Matrix3i effective_point_grid(const std::vector<ViewChange>& changes, int width, int height,
                                     double min_angle_deg) {
  Eigen::Matrix3i grid = Eigen::Matrix3i::Zero();
  for (const auto& c : changes) {
    if (c.angle_deg <= min_angle_deg) continue;
    const int col = std::clamp(static_cast<int>(3.0f * c.u / static_cast<float>(width)), 0, 2);
    const int row = std::clamp(static_cast<int>(3.0f * c.v / static_cast<float>(height)), 0, 2);
    ++grid(row, col);
  }
  return grid;
}

// Reading of Eqs. 2-5 (docs/keyframe_policy.md): cells are indexed by 1-based (row i, column j), so the
// centre cell is (2, 2). Centre of gravity: x = sum(j*M_ij)/sum(M), y = sum(i*M_ij)/sum(M) (Eqs. 2-3).
// Eq. 4, T1 = sqrt(x^2 + y^2), with the origin at the centre cell: T1 = |(x, y) - (2, 2)|, how far the
// mass leans to one side, in [0, sqrt(2)]. With M1 >= M2 the two largest cells at p1, p2:
// T2 = |p1 - p2| * M2 / (2 sqrt(2) M1) (Eq. 5, as printed): 2 sqrt(2) is the corner-to-corner distance,
// so T2 is in [0, 1]. "Spread out" = T2 > T1. An empty grid is not spread out; one occupied cell: T2 = 0.
GridBalance grid_balance(const Eigen::Matrix3i& counts) {
  GridBalance b;
  const double total = counts.sum();
  if (total <= 0) return b;
  double x = 0, y = 0;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      x += (j + 1) * counts(i, j);
      y += (i + 1) * counts(i, j);
    }
  }
  x /= total;
  y /= total;
  b.t1 = std::hypot(x - 2.0, y - 2.0);
  // Two largest cells, ties broken by row-major order so the result is deterministic.
  int i1 = -1, j1 = -1, i2 = -1, j2 = -1;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      if (i1 < 0 || counts(i, j) > counts(i1, j1)) {
        i2 = i1;
        j2 = j1;
        i1 = i;
        j1 = j;
      } else if (i2 < 0 || counts(i, j) > counts(i2, j2)) {
        i2 = i;
        j2 = j;
      }
    }
  }
  const double m1 = counts(i1, j1);
  const double m2 = counts(i2, j2);
  if (m1 <= 0) return b;
  b.t2 = std::hypot(static_cast<double>(i1 - i2), static_cast<double>(j1 - j2)) * m2 /
         (2.0 * std::sqrt(2.0) * m1);
  return b;
}

}  // namespace sp::track
