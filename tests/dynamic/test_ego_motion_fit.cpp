// The MSAC camera-motion fit of the motion check against known transforms.
#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/calib3d.hpp>
#include <random>

#include "stillpoint/dynamic/ego_motion_fit.hpp"

namespace sp::dyn {
namespace {

const cv::Matx33d kK(535.4, 0, 320.1, 0, 539.2, 247.6, 0, 0, 1);

cv::Point2f project(const cv::Vec3d& p) {
  return {static_cast<float>(kK(0, 0) * p[0] / p[2] + kK(0, 2)),
          static_cast<float>(kK(1, 1) * p[1] / p[2] + kK(1, 2))};
}

struct Motion {
  cv::Matx33d R;
  cv::Vec3d t;
};

// A small hand-held step: a fraction of a degree and a centimetre.
Motion step() {
  cv::Mat R;
  cv::Rodrigues(cv::Vec3d(0.004, -0.007, 0.002), R);
  return {cv::Matx33d(R), cv::Vec3d(0.011, -0.004, 0.006)};
}

// A point at pixel (u, v) and depth z of the current camera, observed in the previous image after the
// camera step, plus an optional displacement of the point itself (a mover) and pixel noise.
struct Builder {
  Motion m = step();
  std::mt19937 rng{7};
  double noise_px = 0.0;
  MotionFitPoints pts;
  cv::Point2f noisy(cv::Point2f p) {
    std::normal_distribution<float> n(0.f, static_cast<float>(noise_px));
    if (noise_px > 0.0) p += cv::Point2f(n(rng), n(rng));
    return p;
  }
  cv::Vec3d back_project(double u, double v, double z) const {
    return {(u - kK(0, 2)) * z / kK(0, 0), (v - kK(1, 2)) * z / kK(1, 1), z};
  }
  void add_depth(double u, double v, double z, const cv::Vec3d& moved = {0, 0, 0}) {
    const cv::Vec3d X = back_project(u, v, z);
    pts.cur_3d.emplace_back(static_cast<float>(X[0]), static_cast<float>(X[1]), static_cast<float>(X[2]));
    pts.prev_px.push_back(noisy(project(m.R * (X + moved) + m.t)));
  }
  void add_flat(double u, double v, double z) {
    const cv::Vec3d X = back_project(u, v, z);
    pts.flat_cur_px.emplace_back(static_cast<float>(u), static_cast<float>(v));
    pts.flat_prev_px.push_back(noisy(project(m.R * X + m.t)));
  }
};

double rotation_error_deg(const cv::Matx33d& A, const cv::Matx33d& B) {
  cv::Mat r;
  cv::Rodrigues(cv::Mat(A.t() * B), r);
  return cv::norm(r) * 180.0 / M_PI;
}

double residual_px(const Builder& b, const CameraMotion& m, std::size_t i) {
  const cv::Point3f& X = b.pts.cur_3d[i];
  const cv::Point2f p = project(m.R * cv::Vec3d(X.x, X.y, X.z) + m.t);
  return cv::norm(p - b.pts.prev_px[i]);
}

TEST(EgoMotionFit, RecoversAKnownMotionExactly) {
  Builder b;
  std::uniform_real_distribution<double> u(20, 620), v(20, 460), z(1.5, 4.0);
  for (int i = 0; i < 40; ++i) b.add_depth(u(b.rng), v(b.rng), z(b.rng));
  for (int i = 0; i < 60; ++i) b.add_flat(u(b.rng), v(b.rng), 7.0);
  const auto m = fit_camera_motion_msac(b.pts, kK, std::nullopt, MsacOptions{});
  ASSERT_TRUE(m.has_value());
  EXPECT_LT(rotation_error_deg(m->R, b.m.R), 1e-3);
  EXPECT_LT(cv::norm(m->t - b.m.t), 1e-5);
  EXPECT_EQ(m->inliers, 40);
}

TEST(EgoMotionFit, IgnoresGrossOutliers) {
  Builder b;
  b.noise_px = 0.2;
  std::uniform_real_distribution<double> u(20, 620), v(20, 460), z(1.5, 4.0), jump(-40, 40);
  for (int i = 0; i < 60; ++i) b.add_depth(u(b.rng), v(b.rng), z(b.rng));
  for (int i = 0; i < 25; ++i) {  // 30 % of the points with depth land anywhere
    b.add_depth(u(b.rng), v(b.rng), z(b.rng));
    b.pts.prev_px.back() += cv::Point2f(static_cast<float>(jump(b.rng)), static_cast<float>(jump(b.rng)));
  }
  const auto m = fit_camera_motion_msac(b.pts, kK, std::nullopt, MsacOptions{2.0, 1.0, 200});
  ASSERT_TRUE(m.has_value());
  EXPECT_LT(rotation_error_deg(m->R, b.m.R), 0.05);
  EXPECT_LT(cv::norm(m->t - b.m.t), 2e-3);
  EXPECT_GE(m->inliers, 55);
  EXPECT_LE(m->inliers, 64);
}

// The failure this fit exists for: a person close to the camera walking slowly (2 cm a frame, at 1 m).
// Counting inliers within 2 px, a camera motion 3 cm off explains the person and still keeps the
// background within the threshold; the size of the residuals within 1 px tells them apart.
TEST(EgoMotionFit, FollowsTheBackgroundNotACloseSlowMover) {
  const auto scene = [](Builder& b) {
    b.noise_px = 0.15;
    std::uniform_real_distribution<double> u(20, 620), v(20, 460), z(2.0, 3.5);
    for (int i = 0; i < 30; ++i) b.add_depth(u(b.rng), v(b.rng), z(b.rng));  // desk, floor
    for (int i = 0; i < 100; ++i) b.add_flat(u(b.rng), v(b.rng), 6.0);       // far wall, no depth
    std::uniform_real_distribution<double> pu(480, 620), pv(120, 460), pz(0.9, 1.1);
    for (int i = 0; i < 20; ++i) b.add_depth(pu(b.rng), pv(b.rng), pz(b.rng), cv::Vec3d(0.02, 0.0, 0.0));
  };
  Builder b;
  scene(b);
  const auto m = fit_camera_motion_msac(b.pts, kK, std::nullopt, MsacOptions{1.0, 1.0, 200});
  ASSERT_TRUE(m.has_value());
  EXPECT_LT(rotation_error_deg(m->R, b.m.R), 0.1);
  EXPECT_LT(cv::norm(m->t - b.m.t), 4e-3);
  int background_ok = 0, mover_out = 0;
  for (std::size_t i = 0; i < 30; ++i) background_ok += residual_px(b, *m, i) < 1.0 ? 1 : 0;
  for (std::size_t i = 30; i < 50; ++i) mover_out += residual_px(b, *m, i) > 2.0 ? 1 : 0;
  EXPECT_GE(background_ok, 28);
  EXPECT_EQ(mover_out, 20);
  // The same data truncated at 2 px: the fit follows the person (why the threshold is an option).
  Builder c;
  scene(c);
  const auto loose = fit_camera_motion_msac(c.pts, kK, std::nullopt, MsacOptions{2.0, 1.0, 200});
  ASSERT_TRUE(loose.has_value());
  EXPECT_GT(cv::norm(loose->t - c.m.t), 1e-2);
}

TEST(EgoMotionFit, AGoodGuessIsKeptAndTooFewPointsFail) {
  Builder b;
  std::uniform_real_distribution<double> u(20, 620), v(20, 460), z(1.5, 4.0);
  for (int i = 0; i < 3; ++i) b.add_depth(u(b.rng), v(b.rng), z(b.rng));
  EXPECT_FALSE(fit_camera_motion_msac(b.pts, kK, std::nullopt, MsacOptions{}).has_value());
  for (int i = 0; i < 30; ++i) b.add_depth(u(b.rng), v(b.rng), z(b.rng));
  // No minimal sample at all: the guess alone is scored and refined.
  const auto m = fit_camera_motion_msac(b.pts, kK, CameraMotion{b.m.R, b.m.t, 0}, MsacOptions{1.0, 1.0, 0});
  ASSERT_TRUE(m.has_value());
  EXPECT_LT(cv::norm(m->t - b.m.t), 1e-6);
  EXPECT_EQ(m->inliers, 33);
}

TEST(EgoMotionFit, EpipolarAndTransferDistancesMatchTheirDefinitions) {
  // F of a pure x translation: epipolar lines are horizontal, the distance is the row difference.
  const cv::Matx33d Ki = kK.inv();
  const cv::Matx33d tx(0, 0, 0, 0, 0, -1, 0, 1, 0);  // [t]x for t = (1, 0, 0)
  const cv::Matx33d F = Ki.t() * tx * Ki;
  EXPECT_NEAR(epipolar_line_distance(F, {100.f, 200.f}, {300.f, 203.f}), 3.0, 1e-3);
  const cv::Matx33d H(1, 0, 5, 0, 1, -2, 0, 0, 1);
  EXPECT_NEAR(homography_transfer_error(H, {10.f, 10.f}, {15.f, 12.f}), 4.0, 1e-5);
  EXPECT_LT(homography_transfer_error(cv::Matx33d(1, 0, 0, 0, 1, 0, 0, 0, 0), {1.f, 1.f}, {0.f, 0.f}), 0.f);
}

}  // namespace
}  // namespace sp::dyn
