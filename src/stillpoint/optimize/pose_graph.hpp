#pragma once
// SE(3) pose-graph optimisation (loop closing over the essential graph) with Ceres. Vertices are
// T_cw poses updated on the left (T <- exp(delta) T); an edge measures T_ij = T_iw * T_jw^-1 and
// contributes weight * |log(T_ij^-1 * T_iw * T_jw^-1)|^2 / 2 to the cost. Deterministic with threads = 1.
#include <cstdint>
#include <string>
#include <vector>

#include "stillpoint/common/config_reader.hpp"
#include "stillpoint/geometry/lie.hpp"

namespace sp::opt {

struct PoseGraphVertex {
  std::uint64_t id = 0;
  geo::SE3 T_cw;
  bool fixed = false;
};

struct PoseGraphEdge {
  std::uint64_t i = 0, j = 0;
  geo::SE3 T_ij;      // measured T_i_w * T_j_w^-1
  double weight = 1;  // information scale (>= 0) of the 6-D residual
};

struct PoseGraphConfig {
  int iterations = 20;  // LM iterations, [1, 1000]
  int threads = 1;      // Ceres threads, [1, 64]; 1 is deterministic
  // Sparse Cholesky behind SPARSE_NORMAL_CHOLESKY: "eigen" (default; single-threaded, no OpenMP, so
  // ThreadSanitizer sees all of it) | "suite_sparse" (CHOLMOD; Debian's build runs OpenMP workers that
  // TSan cannot follow, see docs/map_lock.md).
  std::string sparse_library = "eigen";
  static PoseGraphConfig from_yaml(const ConfigReader& r);
};

struct PoseGraphResult {
  double initial_cost = 0, final_cost = 0;  // Ceres cost, 1/2 sum of weighted squared residuals
  int iterations = 0;
};

// Updates the non-fixed vertices in place. Throws sp::Error for duplicate vertex ids, an edge to an
// unknown vertex or a negative weight. The caller fixes the gauge (at least one fixed vertex).
PoseGraphResult optimize_pose_graph(std::vector<PoseGraphVertex>& vertices,
                                    const std::vector<PoseGraphEdge>& edges, const PoseGraphConfig& config);

}  // namespace sp::opt
