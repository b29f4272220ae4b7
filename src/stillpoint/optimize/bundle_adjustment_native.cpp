// The native bundle-adjustment solver: Ceres' Levenberg-Marquardt trust-region loop re-done with an
// explicit Schur complement over fixed-size blocks, for local BA (tens of free keyframes).
//
// Same problem as the Ceres path in bundle_adjustment.cpp: poses T_cw updated on the left
// (SE3Manifold::Plus, T <- exp(delta) T, the convention evaluate_reprojection's J_pose is written
// for), Huber loss with Ceres' robust correction (for Huber it is plain IRLS: J and r scaled by
// sqrt(rho')), cost 1/2 sum rho(chi2). The LM loop follows ceres::internal::TrustRegionMinimizer and
// LevenbergMarquardtStrategy with Ceres' default options step for step, so both solvers take the
// same steps up to rounding:
//   - damping D = diag(J^T J) / radius, computed like Ceres on the Jacobi-scaled Jacobian (column
//     scale 1 / (1 + |J_j|) fixed at the first evaluation, scaled diagonal clamped to [1e-6, 1e32]);
//     radius starts at 1e4; accepted step: radius /= max(1/3, 1 - (2 rho - 1)^3) (at most 1e16);
//     rejected step: radius /= f, f *= 2 (f back to 2 after an accepted step);
//   - a step is accepted when (cost - new cost) / model decrease > 1e-3; the solve stops at the
//     iteration limit, when |cost change| <= 1e-6 cost, when |x - x_new| <= 1e-8 (|x| + 1e-8)
//     (ambient parameters, |x| unknown before the first accepted step, as in Ceres), when
//     max |x - Plus(x, -g)| <= 1e-10 or when the radius drops below 1e-32. A step that ends the
//     solve by a tolerance is not taken and not counted; the result is the last accepted iterate.
//   - final_cost is the minimum of the costs Ceres records per iteration (a rejected iteration
//     records its candidate's cost), as ceres::Solver::Summary::final_cost.
// Linear algebra: per free pose U (6x6), per point V (3x3), per observation of a free pose
// W (6x3); points are eliminated (S = U - sum W V^-1 W^T over the free poses, dense, LLT), then
// back-substituted. No threads; sums run in a fixed order (points in problem order, then their
// observations in problem order), so two runs are bit-identical.
#include "stillpoint/optimize/bundle_adjustment_native.hpp"

#include <spdlog/spdlog.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>

#include "stillpoint/optimize/ceres_terms.hpp"

namespace sp::opt::detail {
namespace {

using geo::Mat6;
using geo::Vec6;
using Mat63 = Eigen::Matrix<double, 6, 3>;

// ceres::Solver::Options defaults (the Ceres path sets none of them).
constexpr double kInitialRadius = 1e4;
constexpr double kMaxRadius = 1e16;
constexpr double kMinRadius = 1e-32;
constexpr double kMinLmDiagonal = 1e-6;
constexpr double kMaxLmDiagonal = 1e32;
constexpr double kMinRelativeDecrease = 1e-3;
constexpr double kFunctionTolerance = 1e-6;
constexpr double kGradientTolerance = 1e-10;
constexpr double kParameterTolerance = 1e-8;
constexpr int kMaxConsecutiveInvalidSteps = 5;

// What the Ceres path takes from ceres::Solver::Summary (defaults as an empty Summary).
struct PassSummary {
  bool ran = false;  // the pass had residuals
  double initial_cost = -1;
  double final_cost = -1;
  int iterations = 0;
  bool user_abort = false;
};

// An observation of the current pass; a pass lists its observations grouped by point.
struct PassObs {
  std::uint32_t obs = 0;   // index into problem.observations
  std::uint32_t kf = 0;    // keyframe index
  std::int32_t pose = -1;  // free pose index, -1 for a fixed keyframe
};

class NativeBundleAdjuster {
 public:
  NativeBundleAdjuster(const BAProblem& problem, const CameraModel& camera, const BAConfig& config,
                       const std::atomic<bool>* abort, BAIndex index)
      : problem_(problem),
        camera_(camera),
        config_(config),
        abort_(abort),
        index_(std::move(index)),
        delta_mono_(std::sqrt(config.chi2_mono)),
        delta_stereo_(std::sqrt(config.chi2_stereo)) {
    poses_.reserve(problem.keyframes.size());
    for (const BAKeyframe& kf : problem.keyframes) poses_.push_back(to_params(kf.T_cw));
    points_.reserve(problem.points.size());
    for (const BAPoint& p : problem.points) points_.push_back(p.p_w);
    sqrt_info_.reserve(problem.observations.size());
    for (const BAObservation& o : problem.observations)
      sqrt_info_.push_back(std::sqrt(std::max(o.inv_sigma2, 0.0)));
    R_.resize(problem.keyframes.size());
    t_.resize(problem.keyframes.size());
  }

  BAResult run() {
    BAResult result;
    result.outlier.assign(problem_.observations.size(), false);
    const PassSummary first = solve(result.outlier, config_.iterations_first);
    result.initial_cost = first.initial_cost;
    result.final_cost = first.final_cost;
    result.iterations = first.iterations;
    result.aborted = first.user_abort;
    classify(result.outlier);
    if (!result.aborted && config_.iterations_second > 0) {
      const PassSummary second = solve(result.outlier, config_.iterations_second);
      if (second.ran) result.final_cost = second.final_cost;
      result.iterations += second.iterations;
      result.aborted = second.user_abort;
      classify(result.outlier);
    }
    return result;
  }

  // Writes the free keyframes and points that have observations (the others are left untouched; the
  // Ceres path also writes those back, through a parameter round trip).
  void write_back(BAProblem& problem) const {
    std::vector<char> kf_seen(poses_.size(), 0), pt_seen(points_.size(), 0);
    for (const std::size_t k : index_.kf) kf_seen[k] = 1;
    for (const std::size_t p : index_.pt) pt_seen[p] = 1;
    for (std::size_t k = 0; k < poses_.size(); ++k) {
      if (kf_seen[k] && !problem.keyframes[k].fixed)
        problem.keyframes[k].T_cw = from_params(poses_[k].data());
    }
    for (std::size_t p = 0; p < points_.size(); ++p) {
      if (pt_seen[p]) problem.points[p].p_w = points_[p];
    }
  }

  BAGradient gradient(const std::vector<bool>& outlier) {
    BAGradient out;
    out.pose.assign(problem_.keyframes.size(), geo::Vec6::Zero());
    out.point.assign(problem_.points.size(), Eigen::Vector3d::Zero());
    build_pass(outlier);
    out.cost = linearize();
    for (std::size_t f = 0; f < free_kf_.size(); ++f) out.pose[free_kf_[f]] = gc_[f];
    for (std::size_t q = 0; q < pass_points_.size(); ++q) out.point[pass_points_[q]] = gp_[q];
    return out;
  }

 private:
  // The observations not flagged as outliers, their points and keyframes; loads every used
  // keyframe's rotation.
  void build_pass(const std::vector<bool>& outlier) {
    const std::size_t nk = problem_.keyframes.size(), np = problem_.points.size();
    std::vector<char> kf_used(nk, 0);
    std::vector<std::uint32_t> count(np, 0);
    for (std::size_t i = 0; i < problem_.observations.size(); ++i) {
      if (outlier[i]) continue;
      kf_used[index_.kf[i]] = 1;
      ++count[index_.pt[i]];
    }
    free_index_.assign(nk, -1);
    free_kf_.clear();
    for (std::size_t k = 0; k < nk; ++k) {
      if (!kf_used[k]) continue;
      load_pose(k, poses_[k].data());
      if (!problem_.keyframes[k].fixed) {
        free_index_[k] = static_cast<std::int32_t>(free_kf_.size());
        free_kf_.push_back(k);
      }
    }
    pass_points_.clear();
    point_begin_.assign(1, 0);
    std::vector<std::uint32_t> slot(np, 0);  // next free entry of each point's group
    for (std::size_t p = 0; p < np; ++p) {
      if (count[p] == 0) continue;
      slot[p] = point_begin_.back();
      pass_points_.push_back(p);
      point_begin_.push_back(point_begin_.back() + count[p]);
    }
    pass_obs_.resize(point_begin_.back());
    for (std::size_t i = 0; i < problem_.observations.size(); ++i) {
      if (outlier[i]) continue;
      const std::size_t k = index_.kf[i];
      pass_obs_[slot[index_.pt[i]]++] = {static_cast<std::uint32_t>(i), static_cast<std::uint32_t>(k),
                                         free_index_[k]};
    }
    // Per point, its observations by free keyframes (indices into pass_obs_).
    free_begin_.assign(1, 0);
    free_obs_.clear();
    std::uint32_t most = 0;
    for (std::size_t q = 0; q < pass_points_.size(); ++q) {
      for (std::uint32_t e = point_begin_[q]; e < point_begin_[q + 1]; ++e) {
        if (pass_obs_[e].pose >= 0) free_obs_.push_back(e);
      }
      free_begin_.push_back(static_cast<std::uint32_t>(free_obs_.size()));
      most = std::max(most, free_begin_[q + 1] - free_begin_[q]);
    }
    const std::size_t nf = free_kf_.size(), nq = pass_points_.size(), ne = pass_obs_.size();
    U_.resize(nf);
    gc_.resize(nf);
    pose_scale_.resize(nf);
    cand_poses_.resize(nf);
    V_.resize(nq);
    gp_.resize(nq);
    point_scale_.resize(nq);
    Vinv_.resize(nq);
    hp_.resize(nq);
    cand_points_.resize(nq);
    W_.resize(ne);
    T_.resize(most);
  }

  // Rotation and translation of keyframe k as ReprojectionCost computes them from the parameters.
  void load_pose(std::size_t k, const double* p) {
    R_[k] = Eigen::Quaterniond(p[3], p[0], p[1], p[2]).normalized().toRotationMatrix();
    t_[k] = Eigen::Vector3d(p[4], p[5], p[6]);
  }

  [[nodiscard]] double robust_cost(const Reprojection& rep, double* weight) const {
    return 0.5 * huber_cost(rep.chi2(), rep.dim == 2 ? delta_mono_ : delta_stereo_, weight);
  }

  // Cost, gradient and Gauss-Newton blocks (IRLS-weighted) at the current state (R_/t_ loaded).
  double linearize() {
    double cost = 0;
    for (std::size_t f = 0; f < free_kf_.size(); ++f) {
      U_[f].setZero();
      gc_[f].setZero();
    }
    for (std::size_t q = 0; q < pass_points_.size(); ++q) {
      Eigen::Matrix3d V = Eigen::Matrix3d::Zero();
      Eigen::Vector3d g = Eigen::Vector3d::Zero();
      const Eigen::Vector3d& X = points_[pass_points_[q]];
      for (std::uint32_t e = point_begin_[q]; e < point_begin_[q + 1]; ++e) {
        const PassObs& po = pass_obs_[e];
        const BAObservation& o = problem_.observations[po.obs];
        const bool free = po.pose >= 0;
        const Reprojection rep = evaluate_reprojection(camera_, R_[po.kf], t_[po.kf], X, o.uv, o.u_right,
                                                       sqrt_info_[po.obs], free, true);
        if (rep.depth <= 0) {  // behind the camera: zero residual and Jacobians, as ReprojectionCost
          W_[e].setZero();
          continue;
        }
        double w = 1;
        cost += robust_cost(rep, &w);
        const Eigen::Matrix3d JpT = w * rep.J_point.transpose();
        V.noalias() += JpT * rep.J_point;
        g.noalias() += JpT * rep.residual;
        if (free) {
          const Mat63 JcT = w * rep.J_pose.transpose();
          U_[po.pose].noalias() += JcT * rep.J_pose;
          gc_[po.pose].noalias() += JcT * rep.residual;
          W_[e].noalias() = JcT * rep.J_point;
        }
      }
      V_[q] = V;
      gp_[q] = g;
    }
    return cost;
  }

  // Cost at the candidate state (cand_poses_, cand_points_); leaves the candidate's R_/t_ loaded.
  double candidate_cost() {
    for (std::size_t f = 0; f < free_kf_.size(); ++f) load_pose(free_kf_[f], cand_poses_[f].data());
    double cost = 0;
    for (std::size_t q = 0; q < pass_points_.size(); ++q) {
      const Eigen::Vector3d& X = cand_points_[q];
      for (std::uint32_t e = point_begin_[q]; e < point_begin_[q + 1]; ++e) {
        const PassObs& po = pass_obs_[e];
        const BAObservation& o = problem_.observations[po.obs];
        const Reprojection rep = evaluate_reprojection(camera_, R_[po.kf], t_[po.kf], X, o.uv, o.u_right,
                                                       sqrt_info_[po.obs], false, false);
        if (rep.depth > 0) cost += robust_cost(rep, nullptr);
      }
    }
    return cost;
  }

  // Ceres' Jacobi scaling, fixed at the first evaluation of a pass.
  void estimate_scale() {
    for (std::size_t f = 0; f < free_kf_.size(); ++f)
      pose_scale_[f] = (1.0 + U_[f].diagonal().array().sqrt()).inverse().matrix();
    for (std::size_t q = 0; q < pass_points_.size(); ++q)
      point_scale_[q] = (1.0 + V_[q].diagonal().array().sqrt()).inverse().matrix();
  }

  // LM damping of one column: Ceres' diagonal of the scaled J^T J, clamped, over the radius, in
  // unscaled variables (= d / radius unless clamped).
  static double damping(double d, double scale, double radius) {
    const double s2 = scale * scale;
    return std::clamp(d * s2, kMinLmDiagonal, kMaxLmDiagonal) / radius / s2;
  }

  // Solves (H + D) h = -g by eliminating the points; false when the reduced system is not positive
  // definite or the step is not finite (Ceres' LINEAR_SOLVER_FAILURE).
  bool compute_step(double radius) {
    const Eigen::Index n = 6 * static_cast<Eigen::Index>(free_kf_.size());
    S_.setZero(n, n);
    rhs_.resize(n);
    for (std::size_t f = 0; f < free_kf_.size(); ++f) {
      Mat6 Ud = U_[f];
      for (int j = 0; j < 6; ++j) Ud(j, j) += damping(U_[f](j, j), pose_scale_[f][j], radius);
      S_.block<6, 6>(6 * static_cast<Eigen::Index>(f), 6 * static_cast<Eigen::Index>(f)) = Ud;
      rhs_.segment<6>(6 * static_cast<Eigen::Index>(f)) = -gc_[f];
    }
    for (std::size_t q = 0; q < pass_points_.size(); ++q) {
      Eigen::Matrix3d Vd = V_[q];
      for (int j = 0; j < 3; ++j) Vd(j, j) += damping(V_[q](j, j), point_scale_[q][j], radius);
      // As Ceres' InvertPSDMatrix for a dynamic-size E block (full rank assumed).
      Vinv_[q] = Vd.selfadjointView<Eigen::Upper>().llt().solve(Eigen::Matrix3d::Identity());
      // The point's observations by free keyframes, and T = W V^-1 for each.
      const std::uint32_t b = free_begin_[q], m = free_begin_[q + 1] - b;
      const std::uint32_t* fe = free_obs_.data() + b;
      for (std::uint32_t i = 0; i < m; ++i) {
        const std::int32_t a = pass_obs_[fe[i]].pose;
        T_[i].noalias() = W_[fe[i]] * Vinv_[q];
        rhs_.segment<6>(6 * a).noalias() += T_[i] * gp_[q];
      }
      for (std::uint32_t i = 0; i < m; ++i) {
        const std::int32_t a = pass_obs_[fe[i]].pose;
        S_.block<6, 6>(6 * a, 6 * a).noalias() -= T_[i] * W_[fe[i]].transpose();
        for (std::uint32_t j = i + 1; j < m; ++j) {
          const std::int32_t c = pass_obs_[fe[j]].pose;
          const Mat6 M = T_[i] * W_[fe[j]].transpose();
          if (a < c) {
            S_.block<6, 6>(6 * a, 6 * c) -= M;
          } else if (a > c) {
            S_.block<6, 6>(6 * c, 6 * a) -= M.transpose();
          } else {  // the same keyframe observed the point twice
            S_.block<6, 6>(6 * a, 6 * a) -= M + M.transpose();
          }
        }
      }
    }
    if (n > 0) {
      llt_.compute(S_);  // reads the upper triangle
      if (llt_.info() != Eigen::Success) return false;
      hc_ = llt_.solve(rhs_);
      if (!hc_.allFinite()) return false;
    } else {
      hc_.resize(0);
    }
    for (std::size_t q = 0; q < pass_points_.size(); ++q) {
      Eigen::Vector3d r = -gp_[q];
      for (std::uint32_t i = free_begin_[q]; i < free_begin_[q + 1]; ++i) {
        const std::uint32_t e = free_obs_[i];
        r.noalias() -= W_[e].transpose() * hc_.segment<6>(6 * pass_obs_[e].pose);
      }
      hp_[q].noalias() = Vinv_[q] * r;
      if (!hp_[q].allFinite()) return false;
    }
    return true;
  }

  // Decrease of the undamped quadratic model, -g.h - h^T H h / 2 (Ceres: -(J h).(f + J h / 2)).
  [[nodiscard]] double model_cost_change() const {
    double gh = 0, hHh = 0;
    for (std::size_t f = 0; f < free_kf_.size(); ++f) {
      const Vec6 h = hc_.segment<6>(6 * static_cast<Eigen::Index>(f));
      gh += gc_[f].dot(h);
      hHh += h.dot(U_[f] * h);
    }
    for (std::size_t q = 0; q < pass_points_.size(); ++q) {
      const Eigen::Vector3d& h = hp_[q];
      gh += gp_[q].dot(h);
      hHh += h.dot(V_[q] * h);
      for (std::uint32_t i = free_begin_[q]; i < free_begin_[q + 1]; ++i) {
        const std::uint32_t e = free_obs_[i];
        hHh += 2.0 * hc_.segment<6>(6 * pass_obs_[e].pose).dot(W_[e] * h);
      }
    }
    return -gh - 0.5 * hHh;
  }

  // Candidate x + h; returns |x - candidate| over the ambient parameters (as Ceres).
  double make_candidate() {
    double step2 = 0;
    for (std::size_t f = 0; f < free_kf_.size(); ++f) {
      const PoseParams& x = poses_[free_kf_[f]];
      manifold_.Plus(x.data(), hc_.data() + 6 * f, cand_poses_[f].data());
      for (int i = 0; i < 7; ++i) step2 += (x[i] - cand_poses_[f][i]) * (x[i] - cand_poses_[f][i]);
    }
    for (std::size_t q = 0; q < pass_points_.size(); ++q) {
      const Eigen::Vector3d& x = points_[pass_points_[q]];
      cand_points_[q] = x + hp_[q];
      step2 += (x - cand_points_[q]).squaredNorm();
    }
    return std::sqrt(step2);
  }

  void accept_candidate() {
    for (std::size_t f = 0; f < free_kf_.size(); ++f) poses_[free_kf_[f]] = cand_poses_[f];
    for (std::size_t q = 0; q < pass_points_.size(); ++q) points_[pass_points_[q]] = cand_points_[q];
  }

  // |x| over the ambient parameters of the pass.
  [[nodiscard]] double state_norm() const {
    double s = 0;
    for (const std::size_t k : free_kf_) {
      for (const double v : poses_[k]) s += v * v;
    }
    for (const std::size_t p : pass_points_) s += points_[p].squaredNorm();
    return std::sqrt(s);
  }

  // max |x - Plus(x, -g)| (Ceres' gradient_max_norm).
  [[nodiscard]] double gradient_max_norm() const {
    double m = 0;
    for (std::size_t f = 0; f < free_kf_.size(); ++f) {
      const PoseParams& x = poses_[free_kf_[f]];
      const Vec6 minus_g = -gc_[f];
      PoseParams y;
      manifold_.Plus(x.data(), minus_g.data(), y.data());
      for (int i = 0; i < 7; ++i) m = std::max(m, std::abs(x[i] - y[i]));
    }
    for (std::size_t q = 0; q < pass_points_.size(); ++q) {
      const Eigen::Vector3d& x = points_[pass_points_[q]];
      m = std::max(m, (x - (x - gp_[q])).lpNorm<Eigen::Infinity>());
    }
    return m;
  }

  [[nodiscard]] bool abort_requested() const {
    return abort_ != nullptr && abort_->load(std::memory_order_relaxed);
  }

  // One LM solve over the observations not marked as outliers (Ceres' TrustRegionMinimizer).
  PassSummary solve(const std::vector<bool>& outlier, int max_iterations) {
    PassSummary s;
    build_pass(outlier);
    if (pass_obs_.empty()) return s;
    s.ran = true;
    const std::vector<PoseParams> start_poses = poses_;
    const std::vector<Eigen::Vector3d> start_points = points_;

    double x_cost = linearize();
    estimate_scale();
    double grad_max = gradient_max_norm();
    s.initial_cost = x_cost;
    s.final_cost = x_cost;
    double x_norm = -1;  // Ceres leaves it invalid until the first accepted step
    double radius = kInitialRadius, decrease_factor = 2.0;
    bool step_successful = true;
    double iteration_cost = x_cost;
    int iteration = 0, invalid_steps = 0;
    for (;;) {
      // End of iteration `iteration` (Ceres' FinalizeIterationAndCheckIfMinimizerCanContinue).
      s.final_cost = std::min(s.final_cost, iteration_cost);
      s.iterations = iteration;
      if (abort_requested()) {
        s.user_abort = true;
        break;
      }
      if (iteration >= max_iterations) break;
      if (step_successful && grad_max <= kGradientTolerance) break;
      if (radius <= kMinRadius) break;

      ++iteration;
      const bool solved = compute_step(radius);
      const double model_change = solved ? model_cost_change() : 0.0;
      if (!solved || !(model_change > 0.0)) {
        if (++invalid_steps >= kMaxConsecutiveInvalidSteps) {
          // Ceres ends with FAILURE and hands back the state it started from.
          spdlog::warn("bundle adjustment (native): {} consecutive invalid steps, pass undone",
                       invalid_steps);
          poses_ = start_poses;
          points_ = start_points;
          s.iterations = iteration - 1;
          return s;
        }
        radius /= decrease_factor;
        decrease_factor *= 2.0;
        step_successful = false;
        iteration_cost = x_cost;
        continue;
      }
      invalid_steps = 0;

      const double step_norm = make_candidate();
      const double new_cost = candidate_cost();
      if (!(step_norm > kParameterTolerance * (x_norm + kParameterTolerance))) break;
      if (!(std::abs(x_cost - new_cost) > kFunctionTolerance * x_cost)) break;
      const double relative_decrease = (x_cost - new_cost) / model_change;
      if (relative_decrease > kMinRelativeDecrease) {
        accept_candidate();  // R_/t_ already hold the candidate's poses
        x_norm = state_norm();
        x_cost = linearize();
        grad_max = gradient_max_norm();
        radius = std::min(kMaxRadius,
                          radius / std::max(1.0 / 3.0, 1.0 - std::pow(2.0 * relative_decrease - 1.0, 3)));
        decrease_factor = 2.0;
        step_successful = true;
        iteration_cost = x_cost;
      } else {
        radius /= decrease_factor;
        decrease_factor *= 2.0;
        step_successful = false;
        iteration_cost = new_cost;
      }
    }
    spdlog::debug("BA pass (native): {} residuals, {} free poses, {} points, {} iterations, cost {} -> {}",
                  pass_obs_.size(), free_kf_.size(), pass_points_.size(), s.iterations, s.initial_cost,
                  s.final_cost);
    return s;
  }

  // chi-square test of every observation at the current state (as the Ceres path, which converts
  // the pose per observation; here once per keyframe, with the same result).
  void classify(std::vector<bool>& outlier) {
    std::vector<char> converted(poses_.size(), 0);
    for (std::size_t i = 0; i < problem_.observations.size(); ++i) {
      const std::size_t k = index_.kf[i];
      if (!converted[k]) {
        const geo::SE3 T = from_params(poses_[k].data());
        R_[k] = T.rotation();
        t_[k] = T.translation();
        converted[k] = 1;
      }
      const BAObservation& o = problem_.observations[i];
      const Reprojection rep = evaluate_reprojection(camera_, R_[k], t_[k], points_[index_.pt[i]], o.uv,
                                                     o.u_right, sqrt_info_[i], false, false);
      outlier[i] = rep.is_outlier(config_.chi2_mono, config_.chi2_stereo);
    }
  }

  const BAProblem& problem_;
  const CameraModel& camera_;
  const BAConfig& config_;
  const std::atomic<bool>* abort_;
  BAIndex index_;
  double delta_mono_, delta_stereo_;
  SE3Manifold manifold_;

  // State (all keyframes and points) and per-observation constants.
  std::vector<PoseParams> poses_;
  std::vector<Eigen::Vector3d> points_;
  std::vector<double> sqrt_info_;
  std::vector<Eigen::Matrix3d> R_;  // per keyframe, as last loaded
  std::vector<Eigen::Vector3d> t_;

  // The pass: free poses, points and observations grouped by point (CSR).
  std::vector<std::int32_t> free_index_;  // per keyframe
  std::vector<std::size_t> free_kf_;      // per free pose: keyframe index
  std::vector<std::size_t> pass_points_;  // per pass point: point index
  std::vector<std::uint32_t> point_begin_;
  std::vector<PassObs> pass_obs_;
  std::vector<std::uint32_t> free_begin_;  // per pass point (CSR into free_obs_)
  std::vector<std::uint32_t> free_obs_;    // observations of free keyframes, indices into pass_obs_

  // Normal equations at the current state, and the step.
  std::vector<Mat6> U_;
  std::vector<Vec6> gc_, pose_scale_;
  std::vector<Eigen::Matrix3d> V_, Vinv_;
  std::vector<Eigen::Vector3d> gp_, point_scale_, hp_;
  std::vector<Mat63> W_;  // per pass observation (free poses only)
  std::vector<Mat63> T_;  // W V^-1 of one point's observations by free keyframes
  Eigen::MatrixXd S_;
  Eigen::VectorXd rhs_, hc_;
  Eigen::LLT<Eigen::MatrixXd, Eigen::Upper> llt_;

  // Candidate state: per free pose, per pass point.
  std::vector<PoseParams> cand_poses_;
  std::vector<Eigen::Vector3d> cand_points_;
};

}  // namespace

BAResult run_native_bundle_adjustment(BAProblem& problem, const CameraModel& camera, const BAConfig& config,
                                      const std::atomic<bool>* abort, BAIndex index) {
  NativeBundleAdjuster adjuster(problem, camera, config, abort, std::move(index));
  BAResult result = adjuster.run();
  adjuster.write_back(problem);
  return result;
}

BAGradient native_ba_gradient(const BAProblem& problem, const CameraModel& camera, const BAConfig& config,
                              const std::vector<bool>& outlier) {
  NativeBundleAdjuster adjuster(problem, camera, config, nullptr, index_observations(problem));
  return adjuster.gradient(outlier);
}

}  // namespace sp::opt::detail
