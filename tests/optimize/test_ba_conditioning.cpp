// opt::keyframe_centre_std: the camera centre's standard deviation a BA problem gives a free keyframe
// (points shared with fixed keyframes, marginalised). Checked against the full normal matrix built
// from numerical derivatives of the residuals and inverted whole, and against the geometry it must
// reflect: points crowded into a small patch of the image pin the centre far worse than points spread
// over it; points nobody else sees pin nothing.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <random>

#include "stillpoint/common/error.hpp"
#include "stillpoint/optimize/ba_conditioning.hpp"
#include "synthetic.hpp"

namespace sp::opt {
namespace {

// Two keyframes (0 fixed, with depth; 1 free, with depth when `stereo`) see `points`; keyframe 1 also
// sees, with depth, `own` points nobody else does.
BAProblem two_view_problem(const std::vector<Eigen::Vector3d>& points, int own, bool stereo) {
  const CameraModel cam = test::test_camera();
  BAProblem problem;
  problem.keyframes.push_back({0, test::camera_pose(0), true});
  problem.keyframes.push_back({1, test::camera_pose(1), false});
  std::uint64_t pid = 0;
  auto observe = [&](std::uint64_t kid, const Eigen::Vector3d& p_w, int octave, bool depth) {
    const geo::SE3& T = problem.keyframes[kid].T_cw;
    const Eigen::Vector3d s = project_stereo(cam, T * p_w);
    BAObservation o;
    o.keyframe_id = kid;
    o.point_id = pid;
    o.uv = s.head<2>();
    o.u_right = depth ? s.z() : -1.0;
    o.inv_sigma2 = 1.0 / std::pow(1.2, 2 * octave);
    problem.observations.push_back(o);
  };
  for (std::size_t i = 0; i < points.size(); ++i, ++pid) {
    problem.points.push_back({pid, points[i]});
    observe(0, points[i], static_cast<int>(i % 3), true);
    observe(1, points[i], static_cast<int>((i + 1) % 3), stereo);
  }
  for (int i = 0; i < own; ++i, ++pid) {
    const Eigen::Vector3d p(0.1 * i, 0.05 * i, 5.0);
    problem.points.push_back({pid, p});
    observe(1, p, 0, true);  // with depth: its block is regular in the reference's full matrix
  }
  return problem;
}

// Points seen by both cameras of two_view_problem, inside an image window of keyframe 1: u, v in
// [u0, u0 + size] x [v0, v0 + size], depth 3-8 m.
std::vector<Eigen::Vector3d> points_in_window(double u0, double v0, double size, int n, unsigned seed) {
  const CameraModel cam = test::test_camera();
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(u0, u0 + size), v(v0, v0 + size), z(3.0, 8.0);
  const geo::SE3 T_wc = test::camera_pose(1).inverse();
  std::vector<Eigen::Vector3d> out;
  while (static_cast<int>(out.size()) < n) {
    const double zz = z(rng), vv = v(rng), uu = u(rng);
    const Eigen::Vector3d p_c((uu - cam.cx) * zz / cam.fx, (vv - cam.cy) * zz / cam.fy, zz);
    const Eigen::Vector3d p_w = T_wc * p_c;
    if ((test::camera_pose(0) * p_w).z() > 0.5) out.push_back(p_w);
  }
  return out;
}

// The reference: the full normal matrix of keyframe 1's pose and every point, from central differences
// of the weighted residuals, inverted whole; the centre's covariance through its numerical Jacobian.
double reference_centre_std(const BAProblem& problem, const CameraModel& cam) {
  const std::size_t n = problem.points.size();
  const std::size_t dim = 6 + 3 * n;
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(dim), static_cast<Eigen::Index>(dim));
  const double h = 1e-6;
  for (const BAObservation& o : problem.observations) {
    const BAKeyframe& k = problem.keyframes[o.keyframe_id];
    const Eigen::Vector3d p = problem.points[o.point_id].p_w;
    auto residual = [&](const geo::Vec6& d_pose, const Eigen::Vector3d& d_point) {
      const geo::SE3 T = geo::SE3::exp(d_pose) * k.T_cw;
      return evaluate_reprojection(cam, T.rotation(), T.translation(), p + d_point, o.uv, o.u_right,
                                   std::sqrt(o.inv_sigma2), false, false)
          .residual;
    };
    Eigen::MatrixXd J = Eigen::MatrixXd::Zero(3, static_cast<Eigen::Index>(dim));
    for (int j = 0; j < 6 && !k.fixed; ++j) {
      geo::Vec6 d = geo::Vec6::Zero();
      d[j] = h;
      J.col(j) = (residual(d, Eigen::Vector3d::Zero()) - residual(-d, Eigen::Vector3d::Zero())) / (2 * h);
    }
    for (int j = 0; j < 3; ++j) {
      Eigen::Vector3d d = Eigen::Vector3d::Zero();
      d[j] = h;
      J.col(static_cast<Eigen::Index>(6 + 3 * o.point_id) + j) =
          (residual(geo::Vec6::Zero(), d) - residual(geo::Vec6::Zero(), -d)) / (2 * h);
    }
    H += J.transpose() * J;
  }
  const Eigen::Matrix<double, 6, 6> S = H.inverse().topLeftCorner<6, 6>();
  const geo::SE3& T = problem.keyframes[1].T_cw;
  Eigen::Matrix<double, 3, 6> Jc;
  for (int j = 0; j < 6; ++j) {
    geo::Vec6 d = geo::Vec6::Zero();
    d[j] = h;
    Jc.col(j) =
        ((geo::SE3::exp(d) * T).inverse().translation() - (geo::SE3::exp(-d) * T).inverse().translation()) /
        (2 * h);
  }
  const Eigen::Matrix3d C = Jc * S * Jc.transpose();
  return std::sqrt(Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(C).eigenvalues().maxCoeff());
}

TEST(KeyframeCentreStd, MatchesTheInverseOfTheFullNumericalNormalMatrix) {
  const CameraModel cam = test::test_camera();
  for (const bool stereo : {true, false}) {
    const BAProblem problem = two_view_problem(points_in_window(100, 80, 300, 40, 7), 5, stereo);
    const std::vector<double> std_m = keyframe_centre_std(problem, cam);
    ASSERT_EQ(std_m.size(), 2u);
    EXPECT_EQ(std_m[0], 0.0) << "fixed keyframes are not evaluated";
    const double reference = reference_centre_std(problem, cam);
    EXPECT_NEAR(std_m[1], reference, 1e-3 * reference) << (stereo ? "stereo" : "mono");
  }
}

TEST(KeyframeCentreStd, PointsCrowdedIntoAPatchPinTheCentreFarWorseThanPointsSpreadOut) {
  const CameraModel cam = test::test_camera();
  const double spread =
      keyframe_centre_std(two_view_problem(points_in_window(40, 40, 560, 80, 3), 0, true), cam)[1];
  const double patch =
      keyframe_centre_std(two_view_problem(points_in_window(40, 300, 50, 80, 3), 0, true), cam)[1];
  EXPECT_GT(patch, 5.0 * spread) << "spread " << spread << " m, patch " << patch << " m";
  // More of the same points: the deviation falls as 1/sqrt(n).
  const double more =
      keyframe_centre_std(two_view_problem(points_in_window(40, 40, 560, 320, 3), 0, true), cam)[1];
  EXPECT_NEAR(more / spread, 0.5, 0.1);
}

TEST(KeyframeCentreStd, MonocularViewsLeaveTheScaleFree) {
  // Without depth in either view, the second camera's distance from the first scales with the points.
  BAProblem problem = two_view_problem(points_in_window(100, 80, 300, 40, 7), 0, false);
  for (auto& o : problem.observations) o.u_right = -1.0;
  EXPECT_TRUE(std::isinf(keyframe_centre_std(problem, test::test_camera())[1]));
}

TEST(KeyframeCentreStd, PointsNobodyElseSeesPinNothing) {
  const BAProblem problem = two_view_problem({}, 30, true);
  EXPECT_TRUE(std::isinf(keyframe_centre_std(problem, test::test_camera())[1]));
}

TEST(KeyframeCentreStd, AnObservationOfAnUnknownPointIsAnError) {
  BAProblem problem = two_view_problem(points_in_window(100, 80, 300, 10, 1), 0, true);
  problem.observations.back().point_id = 999;
  EXPECT_THROW(keyframe_centre_std(problem, test::test_camera()), Error);
}

}  // namespace
}  // namespace sp::opt
