#include <gtest/gtest.h>

#include <map>

#include "stillpoint/common/error.hpp"
#include "stillpoint/optimize/bundle_adjustment.hpp"
#include "synthetic.hpp"

namespace sp::opt {
namespace {

struct Scene {
  BAProblem truth;
  BAProblem problem;        // perturbed start
  std::vector<bool> gross;  // per observation
};

// `keyframes` cameras, `points` points; every point seen by every camera it projects into.
// `pose_step` scales the motion between consecutive cameras (1: test::camera_pose).
Scene make_scene(int keyframes, int points, double pixel_noise, double outlier_ratio, unsigned seed,
                 double pose_step = 1.0) {
  std::mt19937 rng(seed);
  const CameraModel cam = test::test_camera();
  std::normal_distribution<double> n01(0.0, 1.0);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  Scene s;
  for (int k = 0; k < keyframes; ++k)
    s.truth.keyframes.push_back({static_cast<std::uint64_t>(100 + k),
                                 geo::SE3::exp(pose_step * k * test::camera_pose(1).log()), k == 0});
  const auto pts = test::random_points(rng, points);
  for (int i = 0; i < points; ++i) s.truth.points.push_back({static_cast<std::uint64_t>(7 * i + 1), pts[i]});
  for (const BAKeyframe& kf : s.truth.keyframes) {
    for (const BAPoint& p : s.truth.points) {
      const Eigen::Vector3d pc = kf.T_cw * p.p_w;
      if (pc.z() <= 0.1) continue;
      const Eigen::Vector3d proj = project_stereo(cam, pc);
      if (proj.x() < 0 || proj.x() > 640 || proj.y() < 0 || proj.y() > 480) continue;
      BAObservation o;
      o.keyframe_id = kf.id;
      o.point_id = p.id;
      const double sigma = std::pow(1.2, static_cast<int>(u01(rng) * 3));
      o.inv_sigma2 = 1.0 / (sigma * sigma);
      o.uv = proj.head<2>() + pixel_noise * sigma * Eigen::Vector2d(n01(rng), n01(rng));
      if (u01(rng) < 0.6) o.u_right = o.uv.x() - (proj.x() - proj.z()) + pixel_noise * sigma * n01(rng);
      const bool gross = u01(rng) < outlier_ratio;
      if (gross) o.uv += Eigen::Vector2d(u01(rng) < 0.5 ? 40 : -40, u01(rng) < 0.5 ? 30 : -30);
      s.truth.observations.push_back(o);
      s.gross.push_back(gross);
    }
  }
  s.problem = s.truth;
  for (BAKeyframe& kf : s.problem.keyframes) {
    if (!kf.fixed) kf.T_cw = geo::SE3::exp(test::random_xi(rng, 0.03, 0.015)) * kf.T_cw;
  }
  for (BAPoint& p : s.problem.points) p.p_w += 0.05 * Eigen::Vector3d(n01(rng), n01(rng), n01(rng));
  return s;
}

double max_pose_error(const BAProblem& a, const BAProblem& b) {
  double e = 0;
  for (std::size_t k = 0; k < a.keyframes.size(); ++k) {
    e = std::max(e, test::position_error(a.keyframes[k].T_cw, b.keyframes[k].T_cw));
  }
  return e;
}

TEST(BundleAdjustment, ExactDataRecoversTruth) {
  Scene s = make_scene(5, 300, 0.0, 0.0, 1);
  ASSERT_GT(max_pose_error(s.problem, s.truth), 0.02);
  BAConfig cfg;
  cfg.iterations_second = 30;
  const BAResult r = run_bundle_adjustment(s.problem, test::test_camera(), cfg);
  EXPECT_FALSE(r.aborted);
  EXPECT_LT(r.final_cost, 1e-3 * r.initial_cost);
  EXPECT_LT(max_pose_error(s.problem, s.truth), 1e-4);
  // A point seen once without depth is free along its ray; every other point must be exact.
  std::map<std::uint64_t, int> constraints;
  for (const BAObservation& o : s.problem.observations) constraints[o.point_id] += o.u_right >= 0 ? 2 : 1;
  int checked = 0;
  for (std::size_t i = 0; i < s.problem.points.size(); ++i) {
    if (constraints[s.problem.points[i].id] < 2) continue;
    ++checked;
    EXPECT_LT((s.problem.points[i].p_w - s.truth.points[i].p_w).norm(), 1e-4) << i;
  }
  EXPECT_GT(checked, 250);
  for (bool o : r.outlier) EXPECT_FALSE(o);
  EXPECT_GT(r.iterations, 0);
}

TEST(BundleAdjustment, NoisyDataWithOutliers) {
  Scene s = make_scene(5, 300, 0.5, 0.05, 2);
  const double before = max_pose_error(s.problem, s.truth);
  const BAResult r = run_bundle_adjustment(s.problem, test::test_camera(), BAConfig{});
  ASSERT_EQ(r.outlier.size(), s.problem.observations.size());
  EXPECT_LT(r.final_cost, r.initial_cost);
  const double after = max_pose_error(s.problem, s.truth);
  EXPECT_LT(after, 0.01) << "before " << before;
  EXPECT_LT(after, 0.2 * before);
  int gross = 0, gross_flagged = 0, clean_flagged = 0;
  for (std::size_t i = 0; i < r.outlier.size(); ++i) {
    if (s.gross[i]) {
      ++gross;
      gross_flagged += r.outlier[i] ? 1 : 0;
    } else {
      clean_flagged += r.outlier[i] ? 1 : 0;
    }
  }
  EXPECT_GT(gross, 20);
  EXPECT_EQ(gross_flagged, gross);
  EXPECT_LT(clean_flagged, static_cast<int>(r.outlier.size()) / 10);
  // The fixed keyframe did not move.
  EXPECT_EQ(s.problem.keyframes[0].T_cw.matrix(), s.truth.keyframes[0].T_cw.matrix());
}

TEST(BundleAdjustment, DeterministicWithOneThread) {
  Scene a = make_scene(4, 150, 1.0, 0.05, 3);
  Scene b = a;
  run_bundle_adjustment(a.problem, test::test_camera(), BAConfig{});
  run_bundle_adjustment(b.problem, test::test_camera(), BAConfig{});
  for (std::size_t k = 0; k < a.problem.keyframes.size(); ++k) {
    EXPECT_EQ(a.problem.keyframes[k].T_cw.matrix(), b.problem.keyframes[k].T_cw.matrix());
  }
}

TEST(BundleAdjustment, AbortFlagStopsTheSolve) {
  Scene s = make_scene(4, 150, 0.5, 0.0, 4);
  const BAProblem start = s.problem;
  std::atomic<bool> abort{true};
  const BAResult r = run_bundle_adjustment(s.problem, test::test_camera(), BAConfig{}, &abort);
  EXPECT_TRUE(r.aborted);
  EXPECT_EQ(r.iterations, 0);
  for (std::size_t k = 0; k < start.keyframes.size(); ++k) {
    EXPECT_EQ(s.problem.keyframes[k].T_cw.matrix(), start.keyframes[k].T_cw.matrix());
  }
  // Without the flag the same problem is solved.
  abort = false;
  const BAResult r2 = run_bundle_adjustment(s.problem, test::test_camera(), BAConfig{}, &abort);
  EXPECT_FALSE(r2.aborted);
  EXPECT_GT(r2.iterations, 0);
}

TEST(BundleAdjustment, AllKeyframesFixedRefinesPointsOnly) {
  Scene s = make_scene(3, 100, 0.0, 0.0, 6);
  for (std::size_t k = 0; k < s.problem.keyframes.size(); ++k) {
    s.problem.keyframes[k] = s.truth.keyframes[k];
    s.problem.keyframes[k].fixed = true;
  }
  const BAResult r = run_bundle_adjustment(s.problem, test::test_camera(), BAConfig{});
  EXPECT_LT(r.final_cost, 1e-6 * r.initial_cost);
  for (std::size_t k = 0; k < s.problem.keyframes.size(); ++k) {
    EXPECT_EQ(s.problem.keyframes[k].T_cw.matrix(), s.truth.keyframes[k].T_cw.matrix());
  }
}

TEST(BundleAdjustment, RejectsUnknownIds) {
  Scene s = make_scene(2, 20, 0.0, 0.0, 5);
  s.problem.observations.back().point_id = 999999;
  EXPECT_THROW(run_bundle_adjustment(s.problem, test::test_camera(), BAConfig{}), Error);
  Scene d = make_scene(2, 20, 0.0, 0.0, 5);
  d.problem.keyframes[1].id = d.problem.keyframes[0].id;
  EXPECT_THROW(run_bundle_adjustment(d.problem, test::test_camera(), BAConfig{}), Error);
}

TEST(BundleAdjustment, SparseSchurGivesTheSameSolutionWithEigenAndSuiteSparse) {
  // 48 free keyframes above the dense limit: Ceres factorises the reduced camera system sparsely.
  Scene eigen = make_scene(49, 400, 0.5, 0.0, 8, 0.05);
  Scene suite = eigen;
  BAConfig config;
  config.solver = "ceres";
  config.dense_schur_max_keyframes = 10;
  config.sparse_library = "eigen";
  const BAResult a = run_bundle_adjustment(eigen.problem, test::test_camera(), config);
  config.sparse_library = "suite_sparse";
  const BAResult b = run_bundle_adjustment(suite.problem, test::test_camera(), config);
  EXPECT_LT(max_pose_error(eigen.problem, eigen.truth), 0.01);
  EXPECT_LT(max_pose_error(eigen.problem, suite.problem), 1e-6);
  EXPECT_NEAR(a.final_cost, b.final_cost, 1e-6 * b.final_cost);
  EXPECT_EQ(a.outlier, b.outlier);
}

TEST(BundleAdjustment, DenseAndSparseSchurGiveTheSameSolution) {
  Scene dense = make_scene(49, 400, 0.5, 0.0, 8, 0.05);
  Scene sparse = dense;
  BAConfig config;
  config.solver = "ceres";
  const BAResult a = run_bundle_adjustment(dense.problem, test::test_camera(), config);
  config.dense_schur_max_keyframes = 10;
  const BAResult b = run_bundle_adjustment(sparse.problem, test::test_camera(), config);
  EXPECT_LT(max_pose_error(dense.problem, sparse.problem), 1e-6);
  EXPECT_NEAR(a.final_cost, b.final_cost, 1e-6 * b.final_cost);
  EXPECT_EQ(a.outlier, b.outlier);
}

TEST(BundleAdjustment, ConfigFromYaml) {
  const BAConfig c =
      BAConfig::from_yaml(ConfigReader::from_string("iterations_first: 7\nthreads: 2\n", "t.yaml"));
  EXPECT_EQ(c.iterations_first, 7);
  EXPECT_EQ(c.threads, 2);
  EXPECT_EQ(c.iterations_second, 10);
  EXPECT_EQ(c.sparse_library, "suite_sparse");
  EXPECT_EQ(c.dense_schur_max_keyframes, 300);
  EXPECT_THROW(BAConfig::from_yaml(ConfigReader::from_string("chi2_mono: -1\n", "t.yaml")), ConfigError);
  EXPECT_THROW(BAConfig::from_yaml(ConfigReader::from_string("sparse_library: cxsparse\n", "t.yaml")),
               ConfigError);
}

}  // namespace
}  // namespace sp::opt
