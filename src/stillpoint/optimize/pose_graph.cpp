#include "stillpoint/optimize/pose_graph.hpp"

#include <spdlog/spdlog.h>

#include <string>
#include <unordered_map>

#include "stillpoint/common/error.hpp"
#include "stillpoint/optimize/ceres_terms.hpp"

namespace sp::opt {

PoseGraphConfig PoseGraphConfig::from_yaml(const ConfigReader& r) {
  PoseGraphConfig c;
  r.read("iterations", c.iterations, 1, 1000);
  r.read("threads", c.threads, 1, 64);
  r.read_choice("sparse_library", c.sparse_library, {"eigen", "suite_sparse"});
  return c;
}

PoseGraphResult optimize_pose_graph(std::vector<PoseGraphVertex>& vertices,
                                    const std::vector<PoseGraphEdge>& edges, const PoseGraphConfig& config) {
  std::unordered_map<std::uint64_t, std::size_t> index;
  index.reserve(vertices.size());
  for (std::size_t k = 0; k < vertices.size(); ++k) {
    if (!index.emplace(vertices[k].id, k).second) {
      throw Error("optimize_pose_graph: duplicate vertex id " + std::to_string(vertices[k].id));
    }
  }
  std::vector<PoseParams> params;
  params.reserve(vertices.size());
  for (const PoseGraphVertex& v : vertices) params.push_back(to_params(v.T_cw));

  SE3Manifold manifold;
  ceres::Problem::Options popts;
  popts.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(popts);
  std::vector<bool> used(vertices.size(), false);
  for (const PoseGraphEdge& e : edges) {
    const auto a = index.find(e.i);
    const auto b = index.find(e.j);
    if (a == index.end() || b == index.end()) {
      throw Error("optimize_pose_graph: edge " + std::to_string(e.i) + "-" + std::to_string(e.j) +
                  " names an unknown vertex");
    }
    if (!(e.weight >= 0)) throw Error("optimize_pose_graph: negative or NaN edge weight");
    if (a->second == b->second) continue;  // a self-loop carries no information
    problem.AddResidualBlock(new PoseGraphCost(e.T_ij, std::sqrt(e.weight)), nullptr,
                             params[a->second].data(), params[b->second].data());
    used[a->second] = used[b->second] = true;
  }
  PoseGraphResult result;
  if (problem.NumResidualBlocks() == 0) return result;
  for (std::size_t k = 0; k < vertices.size(); ++k) {
    if (!used[k]) continue;
    problem.SetManifold(params[k].data(), &manifold);
    if (vertices[k].fixed) problem.SetParameterBlockConstant(params[k].data());
  }

  ceres::Solver::Options options;
  options.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  options.sparse_linear_algebra_library_type = sparse_library_type(config.sparse_library);
  options.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  options.max_num_iterations = config.iterations;
  options.num_threads = config.threads;
  options.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(options, &problem, &summary);
  if (summary.termination_type == ceres::FAILURE)
    spdlog::warn("pose graph: Ceres failed: {}", summary.message);

  for (std::size_t k = 0; k < vertices.size(); ++k) {
    if (used[k] && !vertices[k].fixed) vertices[k].T_cw = from_params(params[k].data());
  }
  result.initial_cost = summary.initial_cost;
  result.final_cost = summary.final_cost;
  result.iterations = summary.iterations.empty() ? 0 : static_cast<int>(summary.iterations.size()) - 1;
  return result;
}

}  // namespace sp::opt
