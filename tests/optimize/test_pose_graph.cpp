#include <gtest/gtest.h>

#include "stillpoint/common/error.hpp"
#include "stillpoint/optimize/pose_graph.hpp"
#include "synthetic.hpp"

namespace sp::opt {
namespace {

// Ground-truth T_cw of N cameras on a circle of radius 3 m, each looking at the centre.
std::vector<geo::SE3> circle(int n) {
  std::vector<geo::SE3> out;
  for (int k = 0; k < n; ++k) {
    const double a = 2 * M_PI * k / n;
    const Eigen::Vector3d c(3 * std::cos(a), 0.2 * std::sin(3 * a), 3 * std::sin(a));
    const Eigen::Vector3d z = (-c).normalized();
    const Eigen::Vector3d x = Eigen::Vector3d::UnitY().cross(z).normalized();
    Eigen::Matrix3d R_wc;
    R_wc << x, z.cross(x), z;
    out.push_back(geo::SE3(R_wc, c).inverse());
  }
  return out;
}

struct Loop {
  std::vector<geo::SE3> truth;
  std::vector<PoseGraphVertex> vertices;
  std::vector<PoseGraphEdge> edges;
};

// Odometry edges (with optional noise) plus one loop edge; the initial estimate chains odometry
// with a systematic drift, so the loop is open by tens of centimetres.
Loop make_loop(int n, double edge_noise, unsigned seed) {
  std::mt19937 rng(seed);
  Loop l;
  l.truth = circle(n);
  geo::Vec6 drift;
  drift << 0.01, -0.005, 0.02, 0.004, 0.006, -0.003;
  for (int k = 0; k < n; ++k) {
    const int j = (k + 1) % n;
    const geo::SE3 meas =
        geo::SE3::exp(test::random_xi(rng, edge_noise, edge_noise)) * l.truth[k] * l.truth[j].inverse();
    l.edges.push_back(
        {static_cast<std::uint64_t>(k), static_cast<std::uint64_t>(j), meas, k == n - 1 ? 10.0 : 1.0});
  }
  // T_jw = T_ij^-1 * T_iw along the chain, each step corrupted by the drift.
  geo::SE3 T = l.truth[0];
  for (int k = 0; k < n; ++k) {
    l.vertices.push_back({static_cast<std::uint64_t>(k), T, k == 0});
    T = geo::SE3::exp(drift) * l.edges[k].T_ij.inverse() * T;
  }
  return l;
}

double max_error(const Loop& l) {
  double e = 0;
  for (std::size_t k = 0; k < l.truth.size(); ++k)
    e = std::max(e, test::position_error(l.vertices[k].T_cw, l.truth[k]));
  return e;
}

TEST(PoseGraph, ConsistentEdgesRestoreTheLoopExactly) {
  Loop l = make_loop(20, 0.0, 1);
  ASSERT_GT(max_error(l), 0.2);
  const PoseGraphResult r = optimize_pose_graph(l.vertices, l.edges, PoseGraphConfig{});
  EXPECT_LT(max_error(l), 1e-6);
  EXPECT_LT(r.final_cost, 1e-12);
  EXPECT_GT(r.initial_cost, 1e-3);
  EXPECT_GT(r.iterations, 0);
  EXPECT_EQ(l.vertices[0].T_cw.matrix(), l.truth[0].matrix());  // fixed
}

TEST(PoseGraph, NoisyEdgesReduceDrift) {
  Loop l = make_loop(30, 0.002, 2);
  const double before = max_error(l);
  const PoseGraphResult r = optimize_pose_graph(l.vertices, l.edges, PoseGraphConfig{});
  EXPECT_LT(r.final_cost, r.initial_cost);
  EXPECT_LT(max_error(l), 0.1 * before);
}

TEST(PoseGraph, EigenAndSuiteSparseGiveTheSameSolution) {
  Loop eigen = make_loop(300, 0.002, 4);
  // Extra loop edges across the circle make the normal equations less banded.
  for (int k = 0; k < 150; k += 10) {
    const int j = k + 150;
    eigen.edges.push_back({static_cast<std::uint64_t>(k), static_cast<std::uint64_t>(j),
                           eigen.truth[k] * eigen.truth[j].inverse(), 5.0});
  }
  Loop suite = eigen;
  const double before = max_error(eigen);
  PoseGraphConfig config;
  const PoseGraphResult a = optimize_pose_graph(eigen.vertices, eigen.edges, config);
  config.sparse_library = "suite_sparse";
  const PoseGraphResult b = optimize_pose_graph(suite.vertices, suite.edges, config);
  EXPECT_LT(max_error(eigen), 0.1 * before);
  EXPECT_NEAR(a.final_cost, b.final_cost, 1e-9 + 1e-6 * b.final_cost);
  for (std::size_t k = 0; k < eigen.vertices.size(); ++k)
    EXPECT_LT(test::position_error(eigen.vertices[k].T_cw, suite.vertices[k].T_cw), 1e-6) << k;
}

TEST(PoseGraph, RejectsBadInput) {
  Loop l = make_loop(5, 0.0, 3);
  std::vector<PoseGraphEdge> edges = l.edges;
  edges[0].j = 77;
  EXPECT_THROW(optimize_pose_graph(l.vertices, edges, PoseGraphConfig{}), Error);
  edges = l.edges;
  edges[1].weight = -1;
  EXPECT_THROW(optimize_pose_graph(l.vertices, edges, PoseGraphConfig{}), Error);
}

}  // namespace
}  // namespace sp::opt
