// Analytic Jacobians of every residual against central differences through the manifold increment.
#include <gtest/gtest.h>

#include "stillpoint/optimize/residuals.hpp"
#include "synthetic.hpp"

namespace sp::opt {
namespace {

Reprojection eval(const CameraModel& cam, const geo::SE3& T, const Eigen::Vector3d& p,
                  const Eigen::Vector2d& uv, double u_right, double s) {
  return evaluate_reprojection(cam, T.rotation(), T.translation(), p, uv, u_right, s, true, true);
}

void check_reprojection_jacobians(double u_right) {
  const CameraModel cam = test::test_camera();
  std::mt19937 rng(42);
  const double h = 1e-6;
  for (int trial = 0; trial < 5; ++trial) {
    const geo::SE3 T = test::camera_pose(trial);
    const Eigen::Vector3d p = test::random_points(rng, 1)[0];
    const Eigen::Vector2d uv(300.0 + trial, 250.0 - trial);
    const double s = std::sqrt(1.0 / (1.2 * 1.2 * trial + 1.0));
    const Reprojection rep = eval(cam, T, p, uv, u_right, s);
    ASSERT_GT(rep.depth, 0);
    Eigen::Matrix<double, 3, 6> Jpose_num;
    Eigen::Matrix3d Jpoint_num;
    for (int k = 0; k < 6; ++k) {
      const geo::Vec6 d = geo::Vec6::Unit(k) * h;
      Jpose_num.col(k) = (eval(cam, geo::SE3::exp(d) * T, p, uv, u_right, s).residual -
                          eval(cam, geo::SE3::exp(-d) * T, p, uv, u_right, s).residual) /
                         (2 * h);
    }
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d d = Eigen::Vector3d::Unit(k) * h;
      Jpoint_num.col(k) =
          (eval(cam, T, p + d, uv, u_right, s).residual - eval(cam, T, p - d, uv, u_right, s).residual) /
          (2 * h);
    }
    const double scale = Jpose_num.norm();
    EXPECT_GT(scale, 1.0);
    EXPECT_LT((rep.J_pose - Jpose_num).norm(), 1e-6 * scale) << trial;
    EXPECT_LT((rep.J_point - Jpoint_num).norm(), 1e-6 * Jpoint_num.norm()) << trial;
  }
}

TEST(Residuals, MonocularJacobiansMatchNumerical) { check_reprojection_jacobians(-1.0); }
TEST(Residuals, StereoJacobiansMatchNumerical) { check_reprojection_jacobians(280.0); }

TEST(Residuals, HandWorkedProjection) {
  const CameraModel cam{500, 500, 320, 240, 40};
  // p_c = (1, -0.5, 4): u = 500/4 + 320 = 445, v = -62.5 + 240 = 177.5, u_R = 445 - 10 = 435.
  const Eigen::Vector3d p = project_stereo(cam, {1.0, -0.5, 4.0});
  EXPECT_NEAR(p.x(), 445.0, 1e-12);
  EXPECT_NEAR(p.y(), 177.5, 1e-12);
  EXPECT_NEAR(p.z(), 435.0, 1e-12);
  const Reprojection rep = evaluate_reprojection(cam, Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero(),
                                                 {1.0, -0.5, 4.0}, {446.0, 177.5}, 437.0, 0.5, false, false);
  EXPECT_EQ(rep.dim, 3);
  EXPECT_NEAR(rep.residual.x(), 0.5, 1e-12);
  EXPECT_NEAR(rep.residual.z(), 1.0, 1e-12);
  EXPECT_NEAR(rep.chi2(), 1.25, 1e-12);
  const Reprojection behind = evaluate_reprojection(cam, Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero(),
                                                    {0, 0, -1.0}, {0, 0}, -1, 1.0, true, true);
  EXPECT_LE(behind.depth, 0);
}

TEST(Residuals, PoseGraphJacobiansMatchNumerical) {
  std::mt19937 rng(9);
  const double h = 1e-6;
  for (int trial = 0; trial < 5; ++trial) {
    const geo::SE3 Ti = geo::SE3::exp(test::random_xi(rng, 1.0, 0.6));
    const geo::SE3 Tj = geo::SE3::exp(test::random_xi(rng, 1.0, 0.6));
    // A measurement that disagrees with the estimate, so the residual is far from zero.
    const geo::SE3 Tij = geo::SE3::exp(test::random_xi(rng, 0.3, 0.3)) * Ti * Tj.inverse();
    const double sw = 1.7;
    geo::Mat6 Ji, Jj;
    const geo::Vec6 r = pose_graph_residual(Ti, Tj, Tij, sw, &Ji, &Jj);
    EXPECT_GT(r.norm(), 0.1);
    geo::Mat6 Ji_num, Jj_num;
    for (int k = 0; k < 6; ++k) {
      const geo::Vec6 d = geo::Vec6::Unit(k) * h;
      Ji_num.col(k) = (pose_graph_residual(geo::SE3::exp(d) * Ti, Tj, Tij, sw, nullptr, nullptr) -
                       pose_graph_residual(geo::SE3::exp(-d) * Ti, Tj, Tij, sw, nullptr, nullptr)) /
                      (2 * h);
      Jj_num.col(k) = (pose_graph_residual(Ti, geo::SE3::exp(d) * Tj, Tij, sw, nullptr, nullptr) -
                       pose_graph_residual(Ti, geo::SE3::exp(-d) * Tj, Tij, sw, nullptr, nullptr)) /
                      (2 * h);
    }
    EXPECT_LT((Ji - Ji_num).norm(), 1e-6) << trial;
    EXPECT_LT((Jj - Jj_num).norm(), 1e-6) << trial;
  }
}

TEST(Residuals, HuberCost) {
  double w = 0;
  EXPECT_DOUBLE_EQ(huber_cost(4.0, 3.0, &w), 4.0);
  EXPECT_DOUBLE_EQ(w, 1.0);
  // chi2 = 16, delta = 2: 2*2*4 - 4 = 12, weight 2/4.
  EXPECT_DOUBLE_EQ(huber_cost(16.0, 2.0, &w), 12.0);
  EXPECT_DOUBLE_EQ(w, 0.5);
}

}  // namespace
}  // namespace sp::opt
