#include "stillpoint/optimize/bundle_adjustment.hpp"

#include <spdlog/spdlog.h>

#include <memory>
#include <string>
#include <unordered_map>
#include <utility>

#include "stillpoint/common/error.hpp"
#include "stillpoint/optimize/bundle_adjustment_native.hpp"
#include "stillpoint/optimize/ceres_terms.hpp"

namespace sp::opt {
namespace detail {

BAIndex index_observations(const BAProblem& problem) {
  std::unordered_map<std::uint64_t, std::size_t> kf_index, pt_index;
  kf_index.reserve(problem.keyframes.size());
  pt_index.reserve(problem.points.size());
  for (std::size_t i = 0; i < problem.keyframes.size(); ++i) {
    if (!kf_index.emplace(problem.keyframes[i].id, i).second) {
      throw Error("run_bundle_adjustment: duplicate keyframe id " + std::to_string(problem.keyframes[i].id));
    }
  }
  for (std::size_t i = 0; i < problem.points.size(); ++i) {
    if (!pt_index.emplace(problem.points[i].id, i).second) {
      throw Error("run_bundle_adjustment: duplicate point id " + std::to_string(problem.points[i].id));
    }
  }
  BAIndex idx;
  idx.kf.reserve(problem.observations.size());
  idx.pt.reserve(problem.observations.size());
  for (const BAObservation& o : problem.observations) {
    const auto k = kf_index.find(o.keyframe_id);
    const auto p = pt_index.find(o.point_id);
    if (k == kf_index.end() || p == pt_index.end()) {
      throw Error("run_bundle_adjustment: observation of point " + std::to_string(o.point_id) +
                  " in keyframe " + std::to_string(o.keyframe_id) + " names an unknown keyframe or point");
    }
    idx.kf.push_back(k->second);
    idx.pt.push_back(p->second);
  }
  return idx;
}

int count_free_keyframes(const BAProblem& problem, const BAIndex& index) {
  std::vector<bool> observed(problem.keyframes.size(), false);
  for (const std::size_t k : index.kf) observed[k] = true;
  int free = 0;
  for (std::size_t k = 0; k < problem.keyframes.size(); ++k) {
    if (observed[k] && !problem.keyframes[k].fixed) ++free;
  }
  return free;
}

}  // namespace detail

namespace {

using detail::BAIndex;
using detail::index_observations;

class BundleAdjuster {
 public:
  BundleAdjuster(BAProblem& problem, const CameraModel& camera, const BAConfig& config,
                 const std::atomic<bool>* abort, BAIndex index)
      : problem_(problem),
        camera_(camera),
        config_(config),
        index_(std::move(index)),
        huber_mono_(std::sqrt(config.chi2_mono)),
        huber_stereo_(std::sqrt(config.chi2_stereo)),
        abort_callback_(abort) {
    poses_.reserve(problem.keyframes.size());
    for (const BAKeyframe& kf : problem.keyframes) poses_.push_back(to_params(kf.T_cw));
    points_.reserve(problem.points.size());
    for (const BAPoint& p : problem.points) points_.push_back({p.p_w.x(), p.p_w.y(), p.p_w.z()});
    sqrt_info_.reserve(problem.observations.size());
    for (const BAObservation& o : problem.observations)
      sqrt_info_.push_back(std::sqrt(std::max(o.inv_sigma2, 0.0)));
  }

  BAResult run() {
    BAResult result;
    const std::size_t n = problem_.observations.size();
    result.outlier.assign(n, false);
    const ceres::Solver::Summary first = solve(result.outlier, config_.iterations_first);
    result.initial_cost = first.initial_cost;
    result.final_cost = first.final_cost;
    result.iterations = iterations_of(first);
    result.aborted = first.termination_type == ceres::USER_SUCCESS;
    classify(result.outlier);
    if (!result.aborted && config_.iterations_second > 0) {
      const ceres::Solver::Summary second = solve(result.outlier, config_.iterations_second);
      if (second.num_residual_blocks > 0) result.final_cost = second.final_cost;
      result.iterations += iterations_of(second);
      result.aborted = second.termination_type == ceres::USER_SUCCESS;
      classify(result.outlier);
    }
    write_back();
    return result;
  }

 private:
  static int iterations_of(const ceres::Solver::Summary& s) {
    // Ceres lists iteration 0 (the initial state) too.
    return s.iterations.empty() ? 0 : static_cast<int>(s.iterations.size()) - 1;
  }

  // One LM solve over the observations not marked as outliers.
  ceres::Solver::Summary solve(const std::vector<bool>& outlier, int iterations) {
    ceres::Problem::Options popts;
    popts.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    popts.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    ceres::Problem problem(popts);
    std::vector<bool> pose_used(poses_.size(), false), point_used(points_.size(), false);
    for (std::size_t i = 0; i < problem_.observations.size(); ++i) {
      if (outlier[i]) continue;
      const BAObservation& o = problem_.observations[i];
      double* pose = poses_[index_.kf[i]].data();
      double* point = points_[index_.pt[i]].data();
      if (o.u_right < 0) {
        problem.AddResidualBlock(new ReprojectionCost<2>(camera_, o.uv, -1.0, sqrt_info_[i]), &huber_mono_,
                                 pose, point);
      } else {
        problem.AddResidualBlock(new ReprojectionCost<3>(camera_, o.uv, o.u_right, sqrt_info_[i]),
                                 &huber_stereo_, pose, point);
      }
      pose_used[index_.kf[i]] = true;
      point_used[index_.pt[i]] = true;
    }
    ceres::Solver::Summary summary;
    if (problem.NumResidualBlocks() == 0) return summary;

    auto ordering = std::make_shared<ceres::ParameterBlockOrdering>();
    int free_poses = 0;
    for (std::size_t k = 0; k < poses_.size(); ++k) {
      if (!pose_used[k]) continue;
      problem.SetManifold(poses_[k].data(), &manifold_);
      if (problem_.keyframes[k].fixed) {
        problem.SetParameterBlockConstant(poses_[k].data());
      } else {
        ++free_poses;
      }
      ordering->AddElementToGroup(poses_[k].data(), 1);
    }
    for (std::size_t p = 0; p < points_.size(); ++p) {
      if (point_used[p]) ordering->AddElementToGroup(points_[p].data(), 0);
    }

    ceres::Solver::Options options;
    options.linear_solver_type =
        free_poses <= config_.dense_schur_max_keyframes ? ceres::DENSE_SCHUR : ceres::SPARSE_SCHUR;
    options.sparse_linear_algebra_library_type = sparse_library_type(config_.sparse_library);
    options.linear_solver_ordering = ordering;
    options.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
    options.max_num_iterations = iterations;
    options.num_threads = config_.threads;
    options.logging_type = ceres::SILENT;
    options.minimizer_progress_to_stdout = false;
    options.callbacks.push_back(&abort_callback_);
    ceres::Solve(options, &problem, &summary);
    if (summary.termination_type == ceres::FAILURE) {
      spdlog::warn("bundle adjustment: Ceres failed: {}", summary.message);
    }
    spdlog::debug(
        "BA pass: {} residuals, {} free poses, {} iterations, ms: total {:.1f} preprocess {:.1f} linear "
        "{:.1f} "
        "jacobians {:.1f} residuals {:.1f}",
        summary.num_residual_blocks, free_poses, iterations_of(summary), 1e3 * summary.total_time_in_seconds,
        1e3 * summary.preprocessor_time_in_seconds, 1e3 * summary.linear_solver_time_in_seconds,
        1e3 * summary.jacobian_evaluation_time_in_seconds, 1e3 * summary.residual_evaluation_time_in_seconds);
    return summary;
  }

  // chi-square test of every observation at the current state (outliers may come back).
  void classify(std::vector<bool>& outlier) const {
    for (std::size_t i = 0; i < problem_.observations.size(); ++i) {
      const BAObservation& o = problem_.observations[i];
      const geo::SE3 T = from_params(poses_[index_.kf[i]].data());
      const Eigen::Map<const Eigen::Vector3d> p(points_[index_.pt[i]].data());
      const Reprojection rep = evaluate_reprojection(camera_, T.rotation(), T.translation(), p, o.uv,
                                                     o.u_right, sqrt_info_[i], false, false);
      outlier[i] = rep.is_outlier(config_.chi2_mono, config_.chi2_stereo);
    }
  }

  void write_back() {
    for (std::size_t k = 0; k < poses_.size(); ++k) {
      if (!problem_.keyframes[k].fixed) problem_.keyframes[k].T_cw = from_params(poses_[k].data());
    }
    for (std::size_t p = 0; p < points_.size(); ++p) {
      problem_.points[p].p_w = Eigen::Vector3d(points_[p][0], points_[p][1], points_[p][2]);
    }
  }

  BAProblem& problem_;
  const CameraModel& camera_;
  const BAConfig& config_;
  BAIndex index_;
  std::vector<PoseParams> poses_;
  std::vector<std::array<double, 3>> points_;
  std::vector<double> sqrt_info_;
  SE3Manifold manifold_;
  ceres::HuberLoss huber_mono_, huber_stereo_;
  AbortCallback abort_callback_;
};

}  // namespace

BAConfig BAConfig::from_yaml(const ConfigReader& r) {
  BAConfig c;
  r.read("iterations_first", c.iterations_first, 1, 1000);
  r.read("iterations_second", c.iterations_second, 0, 1000);
  r.read("chi2_mono", c.chi2_mono, 0.1, 1000.0);
  r.read("chi2_stereo", c.chi2_stereo, 0.1, 1000.0);
  r.read("threads", c.threads, 1, 64);
  r.read_choice("solver", c.solver, {"native", "ceres"});
  r.read("dense_schur_max_keyframes", c.dense_schur_max_keyframes, 0, 100000);
  r.read_choice("sparse_library", c.sparse_library, {"eigen", "suite_sparse"});
  return c;
}

BAResult run_bundle_adjustment(BAProblem& problem, const CameraModel& camera, const BAConfig& config,
                               const std::atomic<bool>* abort) {
  if (config.solver != "native" && config.solver != "ceres")
    throw Error("run_bundle_adjustment: unknown solver '" + config.solver + "' (native | ceres)");
  BAIndex index = index_observations(problem);  // checks the ids for both solvers
  if (config.solver == "native") {
    const int free_keyframes = detail::count_free_keyframes(problem, index);
    if (free_keyframes <= kNativeBAMaxFreeKeyframes) {
      return detail::run_native_bundle_adjustment(problem, camera, config, abort, std::move(index));
    }
    spdlog::debug("bundle adjustment: {} free keyframes > {}, Ceres instead of the native solver",
                  free_keyframes, kNativeBAMaxFreeKeyframes);
  }
  BundleAdjuster adjuster(problem, camera, config, abort, std::move(index));
  return adjuster.run();
}

}  // namespace sp::opt
