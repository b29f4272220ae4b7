// The Ceres cost functions, through Ceres' own interface: J_ambient * PlusJacobian must equal the
// central-difference derivative of the residual along SE3Manifold::Plus.
#include <gtest/gtest.h>

#include <atomic>

#include "stillpoint/optimize/ceres_terms.hpp"
#include "synthetic.hpp"

namespace sp::opt {
namespace {

// Tangent Jacobians (rows x tangent size of each block) by central differences through Plus.
std::vector<Eigen::MatrixXd> numerical_tangent_jacobians(const ceres::CostFunction& cost,
                                                         std::vector<std::vector<double>> params,
                                                         const std::vector<bool>& is_pose) {
  const SE3Manifold manifold;
  const int rows = cost.num_residuals();
  const double h = 1e-6;
  std::vector<Eigen::MatrixXd> out;
  for (std::size_t b = 0; b < params.size(); ++b) {
    const int tangent = is_pose[b] ? 6 : 3;
    Eigen::MatrixXd J(rows, tangent);
    for (int k = 0; k < tangent; ++k) {
      Eigen::VectorXd rp(rows), rm(rows);
      for (int sign : {1, -1}) {
        std::vector<std::vector<double>> p = params;
        Eigen::VectorXd d = Eigen::VectorXd::Zero(tangent);
        d[k] = sign * h;
        if (is_pose[b]) {
          manifold.Plus(params[b].data(), d.data(), p[b].data());
        } else {
          for (int i = 0; i < 3; ++i) p[b][i] += d[i];
        }
        std::vector<const double*> ptrs;
        for (auto& v : p) ptrs.push_back(v.data());
        cost.Evaluate(ptrs.data(), sign > 0 ? rp.data() : rm.data(), nullptr);
      }
      J.col(k) = (rp - rm) / (2 * h);
    }
    out.push_back(J);
  }
  return out;
}

// Analytic tangent Jacobians: Ceres' ambient Jacobian times the manifold's PlusJacobian.
std::vector<Eigen::MatrixXd> analytic_tangent_jacobians(const ceres::CostFunction& cost,
                                                        std::vector<std::vector<double>> params,
                                                        const std::vector<bool>& is_pose) {
  const SE3Manifold manifold;
  const int rows = cost.num_residuals();
  std::vector<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> amb;
  std::vector<double*> jptrs;
  for (std::size_t b = 0; b < params.size(); ++b) amb.emplace_back(rows, static_cast<int>(params[b].size()));
  for (auto& m : amb) jptrs.push_back(m.data());
  std::vector<const double*> ptrs;
  for (auto& v : params) ptrs.push_back(v.data());
  Eigen::VectorXd r(rows);
  EXPECT_TRUE(cost.Evaluate(ptrs.data(), r.data(), jptrs.data()));
  std::vector<Eigen::MatrixXd> out;
  for (std::size_t b = 0; b < params.size(); ++b) {
    if (is_pose[b]) {
      Eigen::Matrix<double, 7, 6, Eigen::RowMajor> P;
      manifold.PlusJacobian(params[b].data(), P.data());
      out.emplace_back(amb[b] * P);
    } else {
      out.emplace_back(amb[b]);
    }
  }
  return out;
}

std::vector<double> as_vector(const PoseParams& p) { return {p.begin(), p.end()}; }

TEST(CeresTerms, ManifoldPlusMinusAreConsistent) {
  std::mt19937 rng(4);
  const SE3Manifold m;
  const PoseParams x = to_params(geo::SE3::exp(test::random_xi(rng, 1.0, 0.8)));
  const geo::Vec6 d = test::random_xi(rng, 0.1, 0.1);
  PoseParams y;
  m.Plus(x.data(), d.data(), y.data());
  geo::Vec6 back;
  m.Minus(y.data(), x.data(), back.data());
  EXPECT_NEAR((back - d).norm(), 0.0, 1e-12);
  // Plus is the left update exp(d) * T.
  const geo::SE3 expected = geo::SE3::exp(d) * from_params(x.data());
  EXPECT_NEAR((from_params(y.data()).matrix() - expected.matrix()).norm(), 0.0, 1e-12);
}

void check_reprojection_cost(double u_right) {
  const CameraModel cam = test::test_camera();
  std::mt19937 rng(12);
  for (int trial = 0; trial < 4; ++trial) {
    const geo::SE3 T = test::camera_pose(trial);
    const Eigen::Vector3d p = test::random_points(rng, 1)[0];
    const std::vector<std::vector<double>> params = {as_vector(to_params(T)), {p.x(), p.y(), p.z()}};
    std::unique_ptr<ceres::CostFunction> cost;
    if (u_right < 0) {
      cost = std::make_unique<ReprojectionCost<2>>(cam, Eigen::Vector2d(310, 230), -1.0, 0.8);
    } else {
      cost = std::make_unique<ReprojectionCost<3>>(cam, Eigen::Vector2d(310, 230), u_right, 0.8);
    }
    const auto num = numerical_tangent_jacobians(*cost, params, {true, false});
    const auto ana = analytic_tangent_jacobians(*cost, params, {true, false});
    for (std::size_t b = 0; b < 2; ++b) {
      EXPECT_GT(num[b].norm(), 1.0);
      EXPECT_LT((num[b] - ana[b]).norm(), 1e-6 * num[b].norm()) << "block " << b << " trial " << trial;
    }
  }
}

TEST(CeresTerms, MonoReprojectionCostJacobians) { check_reprojection_cost(-1.0); }
TEST(CeresTerms, StereoReprojectionCostJacobians) { check_reprojection_cost(295.0); }

TEST(CeresTerms, PoseGraphCostJacobians) {
  std::mt19937 rng(21);
  for (int trial = 0; trial < 4; ++trial) {
    const geo::SE3 Ti = geo::SE3::exp(test::random_xi(rng, 1.0, 0.7));
    const geo::SE3 Tj = geo::SE3::exp(test::random_xi(rng, 1.0, 0.7));
    const geo::SE3 Tij = geo::SE3::exp(test::random_xi(rng, 0.2, 0.2)) * Ti * Tj.inverse();
    const PoseGraphCost cost(Tij, 2.0);
    const std::vector<std::vector<double>> params = {as_vector(to_params(Ti)), as_vector(to_params(Tj))};
    const auto num = numerical_tangent_jacobians(cost, params, {true, true});
    const auto ana = analytic_tangent_jacobians(cost, params, {true, true});
    for (std::size_t b = 0; b < 2; ++b) {
      EXPECT_LT((num[b] - ana[b]).norm(), 1e-6) << "block " << b << " trial " << trial;
    }
  }
}

// Raises the abort flag at the n-th cost evaluation, i.e. in the middle of a solve.
class RaiseFlagAt final : public ceres::EvaluationCallback {
 public:
  RaiseFlagAt(std::atomic<bool>* flag, int n) : flag_(flag), n_(n) {}
  void PrepareForEvaluation(bool /*jacobians*/, bool /*new_point*/) override {
    if (++calls_ == n_) flag_->store(true);
  }

 private:
  std::atomic<bool>* flag_;
  int n_;
  int calls_ = 0;
};

TEST(CeresTerms, AbortCallbackStopsASolveMidway) {
  // A drifted 4-pose loop that needs several LM iterations.
  std::mt19937 rng(8);
  std::vector<geo::SE3> truth;
  for (int k = 0; k < 4; ++k) truth.push_back(geo::SE3::exp(test::random_xi(rng, 1.0, 0.5)));
  const auto solve = [&](std::atomic<bool>* flag, int raise_at) {
    std::vector<PoseParams> params;
    for (const geo::SE3& T : truth)
      params.push_back(to_params(geo::SE3::exp(test::random_xi(rng, 0.5, 0.5)) * T));
    SE3Manifold manifold;
    ceres::Problem::Options popts;
    popts.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    RaiseFlagAt raiser(flag, raise_at);
    popts.evaluation_callback = &raiser;
    ceres::Problem problem(popts);
    for (int k = 0; k < 4; ++k) {
      const int j = (k + 1) % 4;
      problem.AddResidualBlock(new PoseGraphCost(truth[k] * truth[j].inverse(), 1.0), nullptr,
                               params[k].data(), params[j].data());
    }
    for (auto& p : params) problem.SetManifold(p.data(), &manifold);
    problem.SetParameterBlockConstant(params[0].data());
    AbortCallback abort(flag);
    ceres::Solver::Options options;
    options.max_num_iterations = 50;
    options.function_tolerance = 1e-16;
    options.gradient_tolerance = 1e-16;
    options.parameter_tolerance = 1e-16;
    options.callbacks.push_back(&abort);
    ceres::Solver::Summary summary;
    ceres::Solve(options, &problem, &summary);
    return summary;
  };
  std::atomic<bool> flag{false};
  const ceres::Solver::Summary free_run = solve(&flag, 1000000);
  EXPECT_NE(free_run.termination_type, ceres::USER_SUCCESS);
  ASSERT_GT(free_run.iterations.size(), 4u);
  flag = false;
  const ceres::Solver::Summary stopped = solve(&flag, 3);
  EXPECT_EQ(stopped.termination_type, ceres::USER_SUCCESS);
  EXPECT_LE(stopped.iterations.size(), 3u);
}

}  // namespace
}  // namespace sp::opt
