// The native bundle-adjustment solver against the Ceres path (the reference), and its own checks.
#include <gtest/gtest.h>

#include <atomic>
#include <map>
#include <string>

#include "stillpoint/common/error.hpp"
#include "stillpoint/optimize/bundle_adjustment.hpp"
#include "stillpoint/optimize/bundle_adjustment_native.hpp"
#include "stillpoint/optimize/ceres_terms.hpp"
#include "synthetic.hpp"

namespace sp::opt {
namespace {

struct Solved {
  BAProblem problem;
  BAResult result;
};

Solved solve_with(const BAProblem& start, const std::string& solver, BAConfig cfg = {},
                  const std::atomic<bool>* abort = nullptr) {
  Solved s{start, {}};
  cfg.solver = solver;
  s.result = run_bundle_adjustment(s.problem, test::test_camera(), cfg, abort);
  return s;
}

// Largest camera-centre (m) and rotation (rad) difference over the keyframes.
std::pair<double, double> pose_difference(const BAProblem& a, const BAProblem& b) {
  double dt = 0, dr = 0;
  for (std::size_t k = 0; k < a.keyframes.size(); ++k) {
    dt = std::max(dt, test::position_error(a.keyframes[k].T_cw, b.keyframes[k].T_cw));
    dr = std::max(dr, test::rotation_error(a.keyframes[k].T_cw, b.keyframes[k].T_cw));
  }
  return {dt, dr};
}

// Largest point difference (m) over the points with at least two constraints (a point seen once
// without depth is free along its ray, where rounding is not damped out).
double point_difference(const BAProblem& a, const BAProblem& b) {
  std::map<std::uint64_t, int> constraints;
  for (const BAObservation& o : a.observations) constraints[o.point_id] += o.u_right >= 0 ? 2 : 1;
  double d = 0;
  for (std::size_t i = 0; i < a.points.size(); ++i) {
    if (constraints[a.points[i].id] < 2) continue;
    d = std::max(d, (a.points[i].p_w - b.points[i].p_w).norm());
  }
  return d;
}

double relative(double a, double b) { return std::abs(a - b) / std::max(std::abs(b), 1e-300); }

// Native and Ceres took the same LM path: same costs, iteration count, outliers and solution.
void expect_same_as_ceres(const Solved& native, const Solved& ceres) {
  EXPECT_LT(relative(native.result.initial_cost, ceres.result.initial_cost), 1e-12)
      << native.result.initial_cost << " vs " << ceres.result.initial_cost;
  EXPECT_LT(relative(native.result.final_cost, ceres.result.final_cost), 1e-6)
      << native.result.final_cost << " vs " << ceres.result.final_cost;
  EXPECT_EQ(native.result.iterations, ceres.result.iterations);
  EXPECT_EQ(native.result.aborted, ceres.result.aborted);
  EXPECT_EQ(native.result.outlier, ceres.result.outlier);
  const auto [dt, dr] = pose_difference(native.problem, ceres.problem);
  EXPECT_LT(dt, 1e-6);
  EXPECT_LT(dr, 1e-6);
  EXPECT_LT(point_difference(native.problem, ceres.problem), 1e-6);
}

test::BASceneSpec medium_spec(unsigned seed) {
  test::BASceneSpec spec;
  spec.free_keyframes = 8;
  spec.fixed_keyframes = 4;
  spec.points = 500;
  spec.seed = seed;
  return spec;
}

TEST(NativeBundleAdjustment, SameSolutionAsCeresOnNoisyData) {
  for (unsigned seed : {11u, 12u, 13u}) {
    SCOPED_TRACE(seed);
    const test::BAScene scene = test::make_ba_scene(medium_spec(seed));
    const Solved native = solve_with(scene.problem, "native");
    const Solved ceres = solve_with(scene.problem, "ceres");
    EXPECT_LT(native.result.final_cost, 0.5 * native.result.initial_cost);
    EXPECT_GT(native.result.iterations, 3);
    expect_same_as_ceres(native, ceres);
  }
}

TEST(NativeBundleAdjustment, SameSolutionAsCeresWhenConverged) {
  // Enough iterations for both solvers to stop on a tolerance rather than the iteration limit.
  const test::BAScene scene = test::make_ba_scene(medium_spec(14));
  BAConfig cfg;
  cfg.iterations_first = 50;
  cfg.iterations_second = 50;
  const Solved native = solve_with(scene.problem, "native", cfg);
  const Solved ceres = solve_with(scene.problem, "ceres", cfg);
  EXPECT_LT(native.result.iterations, 100);
  expect_same_as_ceres(native, ceres);
}

TEST(NativeBundleAdjustment, SingleIterationMatchesCeres) {
  const test::BAScene scene = test::make_ba_scene(medium_spec(15));
  BAConfig cfg;
  cfg.iterations_first = 1;
  cfg.iterations_second = 0;
  const Solved native = solve_with(scene.problem, "native", cfg);
  const Solved ceres = solve_with(scene.problem, "ceres", cfg);
  EXPECT_EQ(native.result.iterations, 1);
  expect_same_as_ceres(native, ceres);
  // The first step moved the poses: a wrong increment convention could not match Ceres here.
  EXPECT_GT(pose_difference(native.problem, scene.problem).first, 1e-3);
}

TEST(NativeBundleAdjustment, GrossOutliersFlaggedAsCeresAndTruthRecovered) {
  test::BASceneSpec spec;  // local-BA size: 20 free + 20 fixed keyframes, 2500 points, 90 % stereo
  spec.outlier_ratio = 0.05;
  spec.seed = 21;
  const test::BAScene scene = test::make_ba_scene(spec);
  ASSERT_GT(scene.problem.observations.size(), 12000u);
  const Solved native = solve_with(scene.problem, "native");
  const Solved ceres = solve_with(scene.problem, "ceres");
  expect_same_as_ceres(native, ceres);

  int gross = 0, gross_flagged = 0, clean_flagged = 0;
  for (std::size_t i = 0; i < scene.gross.size(); ++i) {
    if (scene.gross[i]) {
      ++gross;
      gross_flagged += native.result.outlier[i] ? 1 : 0;
    } else {
      clean_flagged += native.result.outlier[i] ? 1 : 0;
    }
  }
  EXPECT_GT(gross, 500);
  EXPECT_EQ(gross_flagged, gross);
  EXPECT_LT(clean_flagged, static_cast<int>(scene.gross.size()) / 10);
  // The accuracy the noise allows: the same solve on the observations without the gross outliers.
  Solved oracle{scene.problem, {}};
  oracle.problem.observations.clear();
  for (std::size_t i = 0; i < scene.gross.size(); ++i) {
    if (!scene.gross[i]) oracle.problem.observations.push_back(scene.problem.observations[i]);
  }
  oracle.result = run_bundle_adjustment(oracle.problem, test::test_camera(), BAConfig{});
  const auto [oracle_t, oracle_r] = pose_difference(oracle.problem, scene.truth);
  const auto [start_t, start_r] = pose_difference(scene.problem, scene.truth);
  const auto [dt, dr] = pose_difference(native.problem, scene.truth);
  EXPECT_GT(start_t, 0.04);
  EXPECT_GT(start_r, 0.02);
  EXPECT_LT(oracle_t, 0.01);  // (7.2 mm, 1.4 mrad at the far end of the free window)
  EXPECT_LT(oracle_r, 2e-3);
  EXPECT_LT(dt, 1.25 * oracle_t) << "start " << start_t << " oracle " << oracle_t;
  EXPECT_LT(dr, 1.25 * oracle_r) << "start " << start_r << " oracle " << oracle_r;
}

TEST(NativeBundleAdjustment, FixedAndUnobservedBlocksAreBitIdentical) {
  test::BAScene scene = test::make_ba_scene(medium_spec(31));
  // A free keyframe and a point that nothing observes.
  scene.problem.keyframes.push_back({999999, test::camera_pose(3), false});
  scene.problem.points.push_back({888888, Eigen::Vector3d(0.1, 0.2, 5.0)});
  const Solved native = solve_with(scene.problem, "native");
  EXPECT_GT(native.result.iterations, 0);
  int fixed = 0;
  for (std::size_t k = 0; k < scene.problem.keyframes.size(); ++k) {
    if (!scene.problem.keyframes[k].fixed) continue;
    ++fixed;
    EXPECT_EQ(native.problem.keyframes[k].T_cw.quaternion().coeffs(),
              scene.problem.keyframes[k].T_cw.quaternion().coeffs());
    EXPECT_EQ(native.problem.keyframes[k].T_cw.translation(), scene.problem.keyframes[k].T_cw.translation());
  }
  EXPECT_EQ(fixed, 4);
  EXPECT_EQ(native.problem.keyframes.back().T_cw.quaternion().coeffs(),
            scene.problem.keyframes.back().T_cw.quaternion().coeffs());
  EXPECT_EQ(native.problem.keyframes.back().T_cw.translation(),
            scene.problem.keyframes.back().T_cw.translation());
  EXPECT_EQ(native.problem.points.back().p_w, scene.problem.points.back().p_w);
}

// The gradient the solver accumulates is the derivative of its cost along SE3Manifold::Plus (the
// left increment exp(delta) T_cw) and along p_w: central differences, Huber region included.
TEST(NativeBundleAdjustment, GradientMatchesFiniteDifferencesOfTheCost) {
  test::BASceneSpec spec = medium_spec(41);
  spec.points = 200;
  spec.outlier_ratio = 0.05;
  spec.stereo_ratio = 0.6;
  const test::BAScene scene = test::make_ba_scene(spec);
  const CameraModel cam = test::test_camera();
  const BAConfig cfg;
  const std::vector<bool> no_outliers(scene.problem.observations.size(), false);
  const detail::BAGradient g = detail::native_ba_gradient(scene.problem, cam, cfg, no_outliers);
  // The Huber kernel is active on some residuals.
  int robust = 0;
  for (std::size_t i = 0; i < scene.problem.observations.size(); ++i) robust += scene.gross[i] ? 1 : 0;
  ASSERT_GT(robust, 10);

  const SE3Manifold manifold;
  const double eps = 1e-6;
  auto cost_with_pose = [&](std::size_t k, const geo::Vec6& delta) {
    BAProblem p = scene.problem;
    const PoseParams x = to_params(p.keyframes[k].T_cw);
    PoseParams y;
    manifold.Plus(x.data(), delta.data(), y.data());
    p.keyframes[k].T_cw = from_params(y.data());
    return detail::native_ba_gradient(p, cam, cfg, no_outliers).cost;
  };
  int checked = 0;
  double right_mismatch = 0;
  for (std::size_t k = 0; k < scene.problem.keyframes.size(); k += 3) {
    if (scene.problem.keyframes[k].fixed) {
      EXPECT_EQ(g.pose[k], geo::Vec6::Zero());
      continue;
    }
    const double scale = std::max(1.0, g.pose[k].lpNorm<Eigen::Infinity>());
    for (int j = 0; j < 6; ++j) {
      geo::Vec6 d = geo::Vec6::Zero();
      d[j] = eps;
      const double fd = (cost_with_pose(k, d) - cost_with_pose(k, -d)) / (2 * eps);
      EXPECT_NEAR(fd, g.pose[k][j], 1e-5 * scale) << "keyframe " << k << " component " << j;
      ++checked;
      // The right increment T exp(delta) gives another derivative: the check can tell them apart.
      BAProblem p = scene.problem;
      p.keyframes[k].T_cw = scene.problem.keyframes[k].T_cw * geo::SE3::exp(d);
      const double c_plus = detail::native_ba_gradient(p, cam, cfg, no_outliers).cost;
      p.keyframes[k].T_cw = scene.problem.keyframes[k].T_cw * geo::SE3::exp(-d);
      const double c_minus = detail::native_ba_gradient(p, cam, cfg, no_outliers).cost;
      right_mismatch =
          std::max(right_mismatch, std::abs((c_plus - c_minus) / (2 * eps) - g.pose[k][j]) / scale);
    }
  }
  EXPECT_GE(checked, 12);
  EXPECT_GT(right_mismatch, 1e-2);
  for (std::size_t i = 0; i < scene.problem.points.size(); i += 37) {
    const double scale = std::max(1.0, g.point[i].lpNorm<Eigen::Infinity>());
    for (int j = 0; j < 3; ++j) {
      BAProblem p = scene.problem;
      p.points[i].p_w[j] += eps;
      const double c_plus = detail::native_ba_gradient(p, cam, cfg, no_outliers).cost;
      p.points[i].p_w[j] -= 2 * eps;
      const double c_minus = detail::native_ba_gradient(p, cam, cfg, no_outliers).cost;
      EXPECT_NEAR((c_plus - c_minus) / (2 * eps), g.point[i][j], 1e-5 * scale) << "point " << i;
    }
  }
}

TEST(NativeBundleAdjustment, AbortBeforeTheSolveMovesNothing) {
  const test::BAScene scene = test::make_ba_scene(medium_spec(51));
  std::atomic<bool> abort{true};
  const Solved native = solve_with(scene.problem, "native", {}, &abort);
  const Solved ceres = solve_with(scene.problem, "ceres", {}, &abort);
  EXPECT_TRUE(native.result.aborted);
  EXPECT_EQ(native.result.iterations, 0);
  EXPECT_EQ(native.result.initial_cost, native.result.final_cost);
  EXPECT_LT(relative(native.result.initial_cost, ceres.result.initial_cost), 1e-12);
  EXPECT_EQ(native.result.outlier, ceres.result.outlier);
  for (std::size_t k = 0; k < scene.problem.keyframes.size(); ++k) {
    EXPECT_EQ(native.problem.keyframes[k].T_cw.matrix(), scene.problem.keyframes[k].T_cw.matrix()) << k;
  }
  for (std::size_t i = 0; i < scene.problem.points.size(); ++i) {
    EXPECT_EQ(native.problem.points[i].p_w, scene.problem.points[i].p_w) << i;
  }
}

TEST(NativeBundleAdjustment, FallsBackToCeresAboveTheFreeKeyframeLimit) {
  test::BASceneSpec spec;
  spec.free_keyframes = kNativeBAMaxFreeKeyframes + 1;
  spec.fixed_keyframes = 1;
  spec.points = 600;
  spec.span = 2;
  spec.seed = 61;
  const test::BAScene above = test::make_ba_scene(spec);
  const Solved native = solve_with(above.problem, "native");
  const Solved ceres = solve_with(above.problem, "ceres");
  // Bit-identical: the Ceres path ran.
  EXPECT_EQ(native.result.initial_cost, ceres.result.initial_cost);
  EXPECT_EQ(native.result.final_cost, ceres.result.final_cost);
  EXPECT_EQ(native.result.iterations, ceres.result.iterations);
  EXPECT_EQ(native.result.outlier, ceres.result.outlier);
  for (std::size_t k = 0; k < above.problem.keyframes.size(); ++k) {
    EXPECT_EQ(native.problem.keyframes[k].T_cw.matrix(), ceres.problem.keyframes[k].T_cw.matrix()) << k;
  }
  for (std::size_t i = 0; i < above.problem.points.size(); ++i) {
    EXPECT_EQ(native.problem.points[i].p_w, ceres.problem.points[i].p_w) << i;
  }

  // At the limit the native solver runs: the same solution, not the same bits (another summation
  // order rounds differently somewhere among thousands of numbers).
  spec.free_keyframes = kNativeBAMaxFreeKeyframes;
  spec.fixed_keyframes = 2;
  const test::BAScene at = test::make_ba_scene(spec);
  const Solved native_at = solve_with(at.problem, "native");
  const Solved ceres_at = solve_with(at.problem, "ceres");
  expect_same_as_ceres(native_at, ceres_at);
  bool any_bit_differs = native_at.result.final_cost != ceres_at.result.final_cost;
  for (std::size_t k = 0; k < at.problem.keyframes.size(); ++k) {
    any_bit_differs = any_bit_differs || native_at.problem.keyframes[k].T_cw.matrix() !=
                                             ceres_at.problem.keyframes[k].T_cw.matrix();
  }
  EXPECT_TRUE(any_bit_differs);
}

TEST(NativeBundleAdjustment, DeterministicBitForBit) {
  test::BASceneSpec spec = medium_spec(71);
  spec.outlier_ratio = 0.05;
  const test::BAScene scene = test::make_ba_scene(spec);
  const Solved a = solve_with(scene.problem, "native");
  const Solved b = solve_with(scene.problem, "native");
  EXPECT_EQ(a.result.initial_cost, b.result.initial_cost);
  EXPECT_EQ(a.result.final_cost, b.result.final_cost);
  EXPECT_EQ(a.result.iterations, b.result.iterations);
  EXPECT_EQ(a.result.outlier, b.result.outlier);
  for (std::size_t k = 0; k < scene.problem.keyframes.size(); ++k) {
    EXPECT_EQ(a.problem.keyframes[k].T_cw.matrix(), b.problem.keyframes[k].T_cw.matrix()) << k;
  }
  for (std::size_t i = 0; i < scene.problem.points.size(); ++i) {
    EXPECT_EQ(a.problem.points[i].p_w, b.problem.points[i].p_w) << i;
  }
}

class NativeBundleAdjustmentKinds : public ::testing::TestWithParam<double> {};

TEST_P(NativeBundleAdjustmentKinds, SameSolutionAsCeres) {
  test::BASceneSpec spec = medium_spec(81);
  spec.stereo_ratio = GetParam();
  spec.outlier_ratio = 0.03;
  spec.fixed_keyframes = 3;  // fixes the scale of the monocular problem too
  const test::BAScene scene = test::make_ba_scene(spec);
  int stereo = 0;
  for (const BAObservation& o : scene.problem.observations) stereo += o.u_right >= 0 ? 1 : 0;
  const int n = static_cast<int>(scene.problem.observations.size());
  if (GetParam() == 0.0) {
    EXPECT_EQ(stereo, 0);
  } else if (GetParam() == 1.0) {
    EXPECT_GT(stereo, n * 99 / 100);  // a virtual right u below 0 makes an observation monocular
  } else {
    EXPECT_TRUE(stereo > n / 4 && stereo < n);
  }
  const Solved native = solve_with(scene.problem, "native");
  const Solved ceres = solve_with(scene.problem, "ceres");
  EXPECT_LT(native.result.final_cost, 0.5 * native.result.initial_cost);
  expect_same_as_ceres(native, ceres);
}

INSTANTIATE_TEST_SUITE_P(MonoStereoMixed, NativeBundleAdjustmentKinds, ::testing::Values(0.0, 1.0, 0.6));

TEST(NativeBundleAdjustment, AllKeyframesFixedMatchesCeres) {
  test::BASceneSpec spec = medium_spec(91);
  spec.fixed_keyframes = 6;
  spec.free_keyframes = 0;
  const test::BAScene scene = test::make_ba_scene(spec);
  expect_same_as_ceres(solve_with(scene.problem, "native"), solve_with(scene.problem, "ceres"));
}

TEST(NativeBundleAdjustment, DuplicateObservationsDoNotBreakIt) {
  test::BAScene scene = test::make_ba_scene(medium_spec(101));
  const std::size_t n = scene.problem.observations.size();
  for (std::size_t i = 0; i < n; i += 10) scene.problem.observations.push_back(scene.problem.observations[i]);
  expect_same_as_ceres(solve_with(scene.problem, "native"), solve_with(scene.problem, "ceres"));
}

TEST(NativeBundleAdjustment, NoObservationsLikeCeres) {
  test::BAScene scene = test::make_ba_scene(medium_spec(111));
  scene.problem.observations.clear();
  const Solved native = solve_with(scene.problem, "native");
  const Solved ceres = solve_with(scene.problem, "ceres");
  EXPECT_EQ(native.result.initial_cost, ceres.result.initial_cost);
  EXPECT_EQ(native.result.final_cost, ceres.result.final_cost);
  EXPECT_EQ(native.result.iterations, 0);
  EXPECT_EQ(ceres.result.iterations, 0);
  EXPECT_FALSE(native.result.aborted);
  EXPECT_TRUE(native.result.outlier.empty());
}

TEST(NativeBundleAdjustment, RejectsUnknownAndDuplicateIds) {
  test::BAScene s = test::make_ba_scene(medium_spec(121));
  s.problem.observations.back().keyframe_id = 424242;
  EXPECT_THROW(solve_with(s.problem, "native"), Error);
  test::BAScene d = test::make_ba_scene(medium_spec(121));
  d.problem.points[1].id = d.problem.points[0].id;
  EXPECT_THROW(solve_with(d.problem, "native"), Error);
}

TEST(NativeBundleAdjustment, SolverChoiceFromYaml) {
  EXPECT_EQ(BAConfig{}.solver, "native");
  EXPECT_EQ(BAConfig::from_yaml(ConfigReader::from_string("solver: ceres\n", "t.yaml")).solver, "ceres");
  EXPECT_EQ(BAConfig::from_yaml(ConfigReader::from_string("solver: native\n", "t.yaml")).solver, "native");
  EXPECT_THROW(BAConfig::from_yaml(ConfigReader::from_string("solver: g2o\n", "t.yaml")), ConfigError);
  BAProblem empty;
  BAConfig bad;
  bad.solver = "g2o";
  EXPECT_THROW(run_bundle_adjustment(empty, test::test_camera(), bad), Error);
}

}  // namespace
}  // namespace sp::opt
