#include "stillpoint/optimize/pose_optimizer.hpp"

#include <Eigen/Cholesky>
#include <cmath>
#include <utility>

namespace sp::opt {
namespace {

struct NormalEquations {
  geo::Mat6 H = geo::Mat6::Zero();
  geo::Vec6 g = geo::Vec6::Zero();
  double cost = 0;
  int used = 0;
};

struct Problem {
  const std::vector<PoseObservation>& obs;
  const std::vector<double>& sqrt_info;
  const std::vector<bool>& outlier;
  const CameraModel& cam;
  double delta_mono, delta_stereo;
  double min_relative_decrease;
  bool robust;
  const PosePrior* prior;
};

// The prior's residual log(T T_p^-1) and its Jacobian for the left increment, d r / d delta = Jl^-1(r).
void add_prior(const PosePrior& prior, const geo::SE3& T, bool with_jacobian, NormalEquations& ne) {
  const geo::Vec6 r = (T * prior.T_cw.inverse()).log();
  geo::Vec6 w;
  w.head<3>().setConstant(1.0 / (prior.sigma_translation_m * prior.sigma_translation_m));
  w.tail<3>().setConstant(1.0 / (prior.sigma_rotation_rad * prior.sigma_rotation_rad));
  ne.cost += r.dot(w.cwiseProduct(r));
  if (!with_jacobian) return;
  const geo::Mat6 J = geo::se3_left_jacobian_inv(r);
  ne.H.noalias() += J.transpose() * w.asDiagonal() * J;
  ne.g.noalias() += J.transpose() * w.cwiseProduct(r);
}

// Gauss-Newton normal equations of the (IRLS-weighted) robust cost at T over the inlier set.
NormalEquations accumulate(const Problem& p, const geo::SE3& T, bool with_jacobian) {
  NormalEquations ne;
  const Eigen::Matrix3d R = T.rotation();
  const Eigen::Vector3d& t = T.translation();
  for (std::size_t i = 0; i < p.obs.size(); ++i) {
    if (p.outlier[i]) continue;
    const PoseObservation& o = p.obs[i];
    const Reprojection rep =
        evaluate_reprojection(p.cam, R, t, o.point_w, o.uv, o.u_right, p.sqrt_info[i], with_jacobian, false);
    if (rep.depth <= 0) continue;
    double w = 1.0;
    const double chi2 = rep.chi2();
    ne.cost += p.robust ? huber_cost(chi2, rep.dim == 2 ? p.delta_mono : p.delta_stereo, &w) : chi2;
    ++ne.used;
    if (!with_jacobian) continue;
    // Unused rows of the monocular residual and Jacobian are zero, so 3 rows serve both cases.
    // A fixed-size product Eigen evaluates inline: rankUpdate goes through its blocked GEMM kernel,
    // ~5x slower at 6x3, and this loop runs for every observation of every LM iteration.
    ne.H.noalias() += w * rep.J_pose.transpose() * rep.J_pose;
    ne.g.noalias() += w * rep.J_pose.transpose() * rep.residual;
  }
  if (p.prior != nullptr) add_prior(*p.prior, T, with_jacobian, ne);
  return ne;
}

// Levenberg-Marquardt on the left increment of T (T <- exp(delta) T).
void levenberg_marquardt(const Problem& p, geo::SE3& T, int iterations) {
  NormalEquations ne = accumulate(p, T, true);
  double lambda = 1e-4;
  for (int it = 0; it < iterations; ++it) {
    if (ne.used < 3) return;
    geo::Mat6 A = ne.H;
    A.diagonal() += lambda * ne.H.diagonal() + geo::Vec6::Constant(1e-12);
    const geo::Vec6 delta = A.ldlt().solve(-ne.g);
    if (!delta.allFinite()) return;
    const geo::SE3 T_new = geo::SE3::exp(delta) * T;
    NormalEquations ne_new = accumulate(p, T_new, true);
    if (ne_new.used >= 3 && ne_new.cost < ne.cost) {
      const double decrease = ne.cost - ne_new.cost;
      T = T_new;
      ne = ne_new;
      lambda = std::max(lambda * 0.1, 1e-9);
      // Converged: a negligible step or cost change (saves most iterations of later rounds).
      if (delta.squaredNorm() < 1e-16 || decrease < p.min_relative_decrease * ne.cost) return;
    } else {
      lambda *= 10.0;
      if (lambda > 1e8) return;
    }
  }
}

// ORB-SLAM's chi-square test of every observation at T_cw, its thresholds scaled by `factor`: marks
// each one above it in `outlier`; returns how many pass.
int classify_outliers(const geo::SE3& T_cw, const std::vector<PoseObservation>& observations,
                      const std::vector<double>& sqrt_info, const CameraModel& camera,
                      const PoseOptimizerConfig& config, double factor, std::vector<bool>& outlier) {
  const Eigen::Matrix3d R = T_cw.rotation();
  int inliers = 0;
  for (std::size_t i = 0; i < observations.size(); ++i) {
    const PoseObservation& o = observations[i];
    const Reprojection rep = evaluate_reprojection(camera, R, T_cw.translation(), o.point_w, o.uv, o.u_right,
                                                   sqrt_info[i], false, false);
    outlier[i] = rep.is_outlier(factor * config.chi2_mono, factor * config.chi2_stereo);
    if (!outlier[i]) ++inliers;
  }
  return inliers;
}

// The start-pose gate (PoseOptimizerConfig::start_outlier_factor): the observations far off at T_cw
// are outliers for the first round, provided T_cw fits at least half of them; else `outlier` stays.
void sit_out_far_off_at_start(const geo::SE3& T_cw, const std::vector<PoseObservation>& observations,
                              const std::vector<double>& sqrt_info, const CameraModel& camera,
                              const PoseOptimizerConfig& config, std::vector<bool>& outlier) {
  std::vector<bool> far_off(observations.size());
  const int fitting = classify_outliers(T_cw, observations, sqrt_info, camera, config, 1.0, far_off);
  if (2 * static_cast<std::size_t>(fitting) < observations.size()) return;
  (void)classify_outliers(T_cw, observations, sqrt_info, camera, config, config.start_outlier_factor,
                          far_off);
  outlier = std::move(far_off);
}

}  // namespace

PoseOptimizerConfig PoseOptimizerConfig::from_yaml(const ConfigReader& r) {
  PoseOptimizerConfig c;
  r.read("rounds", c.rounds, 1, 20);
  r.read("iterations", c.iterations, 1, 100);
  r.read("chi2_mono", c.chi2_mono, 0.1, 1000.0);
  r.read("chi2_stereo", c.chi2_stereo, 0.1, 1000.0);
  r.read("min_relative_decrease", c.min_relative_decrease, 0.0, 0.1);
  r.read("motion_prior_m", c.motion_prior_m, 0.0, 1.0);
  r.read("motion_prior_deg", c.motion_prior_deg, 0.0, 45.0);
  r.read("motion_prior_max_matches", c.motion_prior_max_matches, 0, 100000);
  r.read("start_outlier_factor", c.start_outlier_factor, 0.0, 1000.0);
  r.read("start_outlier_with_prior_only", c.start_outlier_with_prior_only);
  if ((c.motion_prior_m > 0.0) != (c.motion_prior_deg > 0.0))
    r.fail("motion_prior_m", "motion_prior_m and motion_prior_deg are both 0 (no prior) or both > 0");
  return c;
}

PoseOptimizationResult optimize_pose(geo::SE3& T_cw, const std::vector<PoseObservation>& observations,
                                     const CameraModel& camera, const PoseOptimizerConfig& config,
                                     const PosePrior* prior) {
  PoseOptimizationResult result;
  const std::size_t n = observations.size();
  result.outlier.assign(n, false);
  if (n < 3) {
    result.outlier.assign(n, true);
    return result;
  }
  std::vector<double> sqrt_info(n);
  for (std::size_t i = 0; i < n; ++i) sqrt_info[i] = std::sqrt(std::max(observations[i].inv_sigma2, 0.0));

  if (config.start_outlier_factor > 0.0 && (prior != nullptr || !config.start_outlier_with_prior_only))
    sit_out_far_off_at_start(T_cw, observations, sqrt_info, camera, config, result.outlier);
  Problem p{observations,
            sqrt_info,
            result.outlier,
            camera,
            std::sqrt(config.chi2_mono),
            std::sqrt(config.chi2_stereo),
            config.min_relative_decrease,
            true,
            prior};
  for (int round = 0; round < config.rounds; ++round) {
    // The robust kernel is dropped in the last round: by then the outliers are out.
    p.robust = round + 1 < config.rounds;
    levenberg_marquardt(p, T_cw, config.iterations);

    // Re-classify every observation, including last round's outliers (they may come back).
    result.inliers = classify_outliers(T_cw, observations, sqrt_info, camera, config, 1.0, result.outlier);
    if (result.inliers < 10) break;  // too few to trust another round (as ORB-SLAM)
  }
  return result;
}

}  // namespace sp::opt
