#include <gtest/gtest.h>

#include <random>

#include "stillpoint/common/error.hpp"
#include "stillpoint/geometry/alignment.hpp"
#include "stillpoint/geometry/camera.hpp"

namespace sp::geo {
namespace {

std::vector<Eigen::Vector3d> random_points(std::mt19937& rng, int n) {
  std::uniform_real_distribution<double> u(-2.0, 2.0);
  std::vector<Eigen::Vector3d> pts;
  for (int i = 0; i < n; ++i) pts.emplace_back(u(rng), u(rng), u(rng));
  return pts;
}

TEST(Alignment, RecoversRandomRigidAndSimilarity) {
  std::mt19937 rng(7);
  for (bool with_scale : {false, true}) {
    const Eigen::Matrix3d R = Eigen::Quaterniond::UnitRandom().toRotationMatrix();
    const Eigen::Vector3d t(0.3, -1.2, 2.5);
    const double s = with_scale ? 1.7 : 1.0;
    const auto src = random_points(rng, 30);
    std::vector<Eigen::Vector3d> dst;
    for (const auto& p : src) dst.push_back(s * R * p + t);
    const auto est = align_umeyama(src, dst, with_scale);
    EXPECT_LT((est.R - R).norm(), 1e-9);
    EXPECT_LT((est.t - t).norm(), 1e-9);
    EXPECT_NEAR(est.scale, s, 1e-9);
  }
}

TEST(Alignment, RejectsTooFewPairs) {
  std::vector<Eigen::Vector3d> a(2, Eigen::Vector3d::Zero());
  EXPECT_THROW((void)align_umeyama(a, a, false), Error);
}

TEST(Camera, ProjectUnprojectRoundTrip) {
  CameraIntrinsics cam;
  const Eigen::Vector3d p(0.4, -0.2, 2.0);
  const Eigen::Vector2d uv = cam.project(p);
  EXPECT_LT((cam.unproject(uv, p.z()) - p).norm(), 1e-12);
}

TEST(Camera, UndistortInvertsDistort) {
  CameraIntrinsics cam;
  cam.k1 = 0.2624;  // TUM fr1 coefficients
  cam.k2 = -0.9531;
  cam.p1 = -0.0054;
  cam.p2 = 0.0026;
  cam.k3 = 1.1633;
  const Eigen::Vector2d ideal(100.0, 400.0);
  const Eigen::Vector2d d = cam.distort(ideal);
  const auto back = cam.undistort({cv::Point2f(static_cast<float>(d.x()), static_cast<float>(d.y()))});
  EXPECT_NEAR(back[0].x, ideal.x(), 0.05);
  EXPECT_NEAR(back[0].y, ideal.y(), 0.05);
}

}  // namespace
}  // namespace sp::geo
