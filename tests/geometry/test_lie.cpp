#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "stillpoint/geometry/lie.hpp"

namespace {
using sp::geo::Mat6;
using sp::geo::SE3;
using sp::geo::Vec6;

Eigen::Vector3d axis_angle(const Eigen::Vector3d& axis, double angle) { return axis.normalized() * angle; }

Vec6 random_xi(std::mt19937& rng, double scale_t, double scale_r) {
  std::normal_distribution<double> n(0.0, 1.0);
  Vec6 xi;
  for (int i = 0; i < 3; ++i) xi[i] = scale_t * n(rng);
  for (int i = 3; i < 6; ++i) xi[i] = scale_r * n(rng);
  return xi;
}

TEST(Lie, HatIsCrossProduct) {
  const Eigen::Vector3d a(0.3, -1.2, 2.0), b(-0.7, 0.4, 1.1);
  EXPECT_NEAR((sp::geo::hat(a) * b - a.cross(b)).norm(), 0.0, 1e-15);
}

TEST(Lie, So3ExpMatchesAngleAxis) {
  const Eigen::Vector3d axis = Eigen::Vector3d(1, 2, -0.5).normalized();
  for (double angle : {0.0, 1e-12, 1e-7, 1e-3, 0.5, 2.0, M_PI - 1e-9}) {
    const Eigen::Matrix3d R = sp::geo::so3_exp(axis * angle);
    const Eigen::Matrix3d ref = Eigen::AngleAxisd(angle, axis).toRotationMatrix();
    EXPECT_NEAR((R - ref).norm(), 0.0, 1e-14) << angle;
    EXPECT_NEAR(sp::geo::rotation_angle(R), angle, 1e-12) << angle;
  }
}

TEST(Lie, So3LogRoundTripIncludingTinyAndNearPi) {
  const Eigen::Vector3d axis = Eigen::Vector3d(-0.2, 0.9, 0.4).normalized();
  for (double angle : {1e-14, 1e-9, 1e-5, 1e-2, 1.0, 3.0, M_PI - 1e-6, M_PI - 1e-10}) {
    const Eigen::Vector3d phi = axis_angle(axis, angle);
    const Eigen::Vector3d back = sp::geo::so3_log(sp::geo::so3_exp(phi));
    EXPECT_LE((back - phi).norm(), 1e-9 * std::max(1.0, angle) + 1e-20) << angle;
    if (angle < 1e-3) {
      EXPECT_NEAR((back - phi).norm() / angle, 0.0, 1e-9) << "relative, " << angle;
    }
  }
  // Exactly pi: either sign of the axis is a valid answer.
  const Eigen::Vector3d back = sp::geo::so3_log(sp::geo::so3_exp(axis * M_PI));
  EXPECT_NEAR(back.norm(), M_PI, 1e-9);
  EXPECT_NEAR(std::abs(back.normalized().dot(axis)), 1.0, 1e-9);
}

TEST(Lie, So3JacobiansMatchNumerical) {
  const double h = 1e-6;
  for (double angle : {1e-6, 0.3, 2.5}) {
    const Eigen::Vector3d phi = axis_angle(Eigen::Vector3d(0.5, -1, 0.2), angle);
    const Eigen::Matrix3d R = sp::geo::so3_exp(phi);
    Eigen::Matrix3d Jr_num, Jl_num;
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d d = Eigen::Vector3d::Unit(k) * h;
      // exp(phi + d) = exp(phi) exp(Jr d)  =>  Jr d = log(exp(phi)^T exp(phi + d)).
      Jr_num.col(k) = (sp::geo::so3_log(R.transpose() * sp::geo::so3_exp(phi + d)) -
                       sp::geo::so3_log(R.transpose() * sp::geo::so3_exp(phi - d))) /
                      (2 * h);
      Jl_num.col(k) = (sp::geo::so3_log(sp::geo::so3_exp(phi + d) * R.transpose()) -
                       sp::geo::so3_log(sp::geo::so3_exp(phi - d) * R.transpose())) /
                      (2 * h);
    }
    EXPECT_NEAR((sp::geo::so3_right_jacobian(phi) - Jr_num).norm(), 0.0, 1e-7) << angle;
    EXPECT_NEAR((sp::geo::so3_left_jacobian(phi) - Jl_num).norm(), 0.0, 1e-7) << angle;
    EXPECT_NEAR((sp::geo::so3_right_jacobian_inv(phi) * sp::geo::so3_right_jacobian(phi) -
                 Eigen::Matrix3d::Identity())
                    .norm(),
                0.0, 1e-12);
    EXPECT_NEAR(
        (sp::geo::so3_left_jacobian_inv(phi) * sp::geo::so3_left_jacobian(phi) - Eigen::Matrix3d::Identity())
            .norm(),
        0.0, 1e-12);
  }
}

TEST(Lie, Se3ExpLogRoundTrip) {
  std::mt19937 rng(7);
  for (int i = 0; i < 50; ++i) {
    const double rscale = i < 10 ? 1e-9 : (i < 20 ? 1e-4 : 0.8);
    Vec6 xi = random_xi(rng, 2.0, rscale);
    if (xi.tail<3>().norm() > 3.0) continue;
    const Vec6 back = SE3::exp(xi).log();
    EXPECT_NEAR((back - xi).norm(), 0.0, 1e-10) << i;
  }
  // Near pi.
  Vec6 xi;
  xi << 0.4, -1.0, 2.0, axis_angle(Eigen::Vector3d(1, 1, 0), M_PI - 1e-7);
  EXPECT_NEAR((SE3::exp(xi).log() - xi).norm(), 0.0, 1e-6);
}

TEST(Lie, Se3ExpMatchesMatrixExponential) {
  // A pure translation and a pure rotation have exactly known exponentials.
  Vec6 xi = Vec6::Zero();
  xi.head<3>() << 1, 2, 3;
  EXPECT_NEAR((SE3::exp(xi).translation() - Eigen::Vector3d(1, 2, 3)).norm(), 0.0, 1e-15);
  // Screw motion: rotation by pi/2 about z with rho along z keeps translation rho (parallel).
  xi << 0, 0, 0.5, 0, 0, M_PI / 2;
  const SE3 T = SE3::exp(xi);
  EXPECT_NEAR((T.translation() - Eigen::Vector3d(0, 0, 0.5)).norm(), 0.0, 1e-14);
  // rho = (1,0,0), phi = (0,0,pi/2): t = Jl(phi) rho = (sin/θ, (1-cos)/θ, 0).
  xi << 1, 0, 0, 0, 0, M_PI / 2;
  const double th = M_PI / 2;
  EXPECT_NEAR(
      (SE3::exp(xi).translation() - Eigen::Vector3d(std::sin(th) / th, (1 - std::cos(th)) / th, 0)).norm(),
      0.0, 1e-14);
}

TEST(Lie, Se3GroupOperations) {
  std::mt19937 rng(3);
  const SE3 A = SE3::exp(random_xi(rng, 1.0, 0.7));
  const SE3 B = SE3::exp(random_xi(rng, 1.0, 0.7));
  const Eigen::Vector3d p(0.3, -0.2, 1.5);
  EXPECT_NEAR(((A * B) * p - A * (B * p)).norm(), 0.0, 1e-13);
  EXPECT_NEAR(((A * A.inverse()).matrix() - Eigen::Matrix4d::Identity()).norm(), 0.0, 1e-14);
  EXPECT_NEAR(((A * B).matrix() - A.matrix() * B.matrix()).norm(), 0.0, 1e-13);
  EXPECT_NEAR((SE3::from_matrix(A.matrix()).matrix() - A.matrix()).norm(), 0.0, 1e-14);
  const Eigen::Vector4d ph = A.matrix() * p.homogeneous();
  EXPECT_NEAR((ph.head<3>() - A * p).norm(), 0.0, 1e-14);
}

TEST(Lie, AdjointIdentity) {
  std::mt19937 rng(11);
  for (int i = 0; i < 10; ++i) {
    const SE3 T = SE3::exp(random_xi(rng, 1.5, 0.9));
    const Vec6 xi = random_xi(rng, 0.5, 0.5);
    const SE3 lhs = T * SE3::exp(xi) * T.inverse();
    const SE3 rhs = SE3::exp(T.adjoint() * xi);
    EXPECT_NEAR((lhs.matrix() - rhs.matrix()).norm(), 0.0, 1e-12);
  }
}

TEST(Lie, Se3JacobiansMatchNumerical) {
  std::mt19937 rng(5);
  const double h = 1e-6;
  for (double rscale : {1e-7, 1e-3, 0.05, 0.6, 1.2}) {
    const Vec6 xi = random_xi(rng, 1.0, rscale);
    const SE3 T = SE3::exp(xi);
    Mat6 Jl_num, Jr_num;
    for (int k = 0; k < 6; ++k) {
      const Vec6 d = Vec6::Unit(k) * h;
      Jl_num.col(k) =
          ((SE3::exp(xi + d) * T.inverse()).log() - (SE3::exp(xi - d) * T.inverse()).log()) / (2 * h);
      Jr_num.col(k) =
          ((T.inverse() * SE3::exp(xi + d)).log() - (T.inverse() * SE3::exp(xi - d)).log()) / (2 * h);
    }
    EXPECT_NEAR((sp::geo::se3_left_jacobian(xi) - Jl_num).norm(), 0.0, 1e-7) << rscale;
    EXPECT_NEAR((sp::geo::se3_right_jacobian(xi) - Jr_num).norm(), 0.0, 1e-7) << rscale;
    EXPECT_NEAR(
        (sp::geo::se3_left_jacobian_inv(xi) * sp::geo::se3_left_jacobian(xi) - Mat6::Identity()).norm(), 0.0,
        1e-10);
    EXPECT_NEAR(
        (sp::geo::se3_right_jacobian_inv(xi) * sp::geo::se3_right_jacobian(xi) - Mat6::Identity()).norm(),
        0.0, 1e-10);
    // First order: Jl ≈ I + ad/2.
    if (rscale < 1e-2) {
      const Vec6 small = xi * 1e-4;
      EXPECT_NEAR(
          (sp::geo::se3_left_jacobian(small) - Mat6::Identity() - 0.5 * sp::geo::se3_ad(small)).norm(), 0.0,
          1e-7);
    }
  }
}

}  // namespace
