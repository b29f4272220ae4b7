// The new-point motion check alone, on generated images with a known camera motion: a wall at 2 m
// seen by a camera stepping sideways, and a textured "person" at 1 m that moves on its own.
#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "stillpoint/common/error.hpp"
#include "stillpoint/tracking/new_point_motion_check.hpp"

namespace sp::track {
namespace {

constexpr double kWall = 2.0, kPerson = 1.0, kStep = 0.02;  // m
constexpr int kPatch = 100, kPatchX = 300, kPatchY = 200;   // the person's square in the current image

geo::CameraIntrinsics camera() {
  geo::CameraIntrinsics c;
  c.fx = c.fy = 500;
  c.cx = 320;
  c.cy = 240;
  return c;
}

cv::Mat texture(cv::Size size, int seed) {
  cv::Mat t(size, CV_8UC1);
  cv::RNG rng(seed);
  rng.fill(t, cv::RNG::UNIFORM, 0, 255);
  cv::GaussianBlur(t, t, cv::Size(0, 0), 2.0);
  cv::normalize(t, t, 0, 255, cv::NORM_MINMAX);
  return t;
}

struct Scene {
  cv::Mat prev, cur;
  std::vector<Eigen::Vector2d> px;
  std::vector<double> depth;
  std::size_t wall_points = 0;  // the first ones; the rest lie on the person
};

// The camera centre moves kStep to the right between the frames, so a static point at depth z sits
// f * kStep / z px further right in the previous image. The person sits `person_extra_px` further
// right still in the previous image (0: it is static too).
Scene make_scene(double person_extra_px) {
  const geo::CameraIntrinsics c = camera();
  const int wall_shift = static_cast<int>(c.fx * kStep / kWall);  // 5 px
  const int person_shift = static_cast<int>(c.fx * kStep / kPerson + person_extra_px);
  const cv::Mat wall = texture({720, 560}, 1), person = texture({kPatch, kPatch}, 2);
  Scene s;
  s.cur = wall(cv::Rect(40, 40, 640, 480)).clone();
  s.prev = wall(cv::Rect(40 - wall_shift, 40, 640, 480)).clone();
  person.copyTo(s.cur(cv::Rect(kPatchX, kPatchY, kPatch, kPatch)));
  person.copyTo(s.prev(cv::Rect(kPatchX + person_shift, kPatchY, kPatch, kPatch)));
  const cv::Rect2d keep_off(kPatchX - 40, kPatchY - 40, kPatch + 80, kPatch + 80);
  for (int y = 40; y < 440; y += 20)
    for (int x = 40; x < 600; x += 20)
      if (!keep_off.contains(cv::Point2d(x, y))) s.px.emplace_back(x, y), s.depth.push_back(kWall);
  s.wall_points = s.px.size();
  for (int y = kPatchY + 20; y <= kPatchY + kPatch - 20; y += 15)
    for (int x = kPatchX + 20; x <= kPatchX + kPatch - 20; x += 15)
      s.px.emplace_back(x, y), s.depth.push_back(kPerson);
  return s;
}

geo::SE3 step_right() { return geo::SE3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(kStep, 0, 0)); }

NewPointMotionCheckConfig on(double px) {
  NewPointMotionCheckConfig c;
  c.max_residual_px = px;
  return c;
}

std::size_t count_moved(const std::vector<bool>& still, std::size_t from, std::size_t to) {
  std::size_t n = 0;
  for (std::size_t i = from; i < to; ++i) n += still[i] ? 0 : 1;
  return n;
}

TEST(NewPointMotionCheck, APersonMovingAgainstTheCameraIsCaughtTheWallIsNot) {
  const Scene s = make_scene(4.0);  // the person moved 4 px (8 mm at 1 m) against its static place
  const NewPointMotionCheck check(on(2.0), camera());
  const std::vector<bool> still = check.static_candidates(s.prev, s.cur, step_right(), s.px, s.depth);
  ASSERT_EQ(still.size(), s.px.size());
  EXPECT_EQ(count_moved(still, 0, s.wall_points), 0u);
  EXPECT_EQ(count_moved(still, s.wall_points, s.px.size()), s.px.size() - s.wall_points);
}

TEST(NewPointMotionCheck, AStaticCloseObjectIsKept) {
  // The person stands still: at 1 m it moves twice as far in the image as the wall, as parallax says.
  const Scene s = make_scene(0.0);
  const NewPointMotionCheck check(on(2.0), camera());
  const std::vector<bool> still = check.static_candidates(s.prev, s.cur, step_right(), s.px, s.depth);
  EXPECT_EQ(count_moved(still, 0, s.px.size()), 0u);
}

TEST(NewPointMotionCheck, TheTrackedMotionDecidesNotTheImageAlone) {
  // Told the camera did not move, the wall's 5 px shift is a motion and every point is caught.
  const Scene s = make_scene(0.0);
  const NewPointMotionCheck check(on(2.0), camera());
  const std::vector<bool> still = check.static_candidates(s.prev, s.cur, geo::SE3(), s.px, s.depth);
  EXPECT_EQ(count_moved(still, 0, s.wall_points), s.wall_points);
}

TEST(NewPointMotionCheck, OffOrWithoutFlowEveryCandidateIsKept) {
  const Scene s = make_scene(4.0);
  const NewPointMotionCheck off(on(0.0), camera());
  EXPECT_EQ(count_moved(off.static_candidates(s.prev, s.cur, step_right(), s.px, s.depth), 0, s.px.size()),
            0u);
  // A blank previous image gives no flow: nothing can be judged, nothing is dropped.
  const NewPointMotionCheck check(on(2.0), camera());
  const cv::Mat blank(s.cur.size(), CV_8UC1, cv::Scalar(128));
  EXPECT_EQ(count_moved(check.static_candidates(blank, s.cur, step_right(), s.px, s.depth), 0, s.px.size()),
            0u);
  // Candidates without depth are kept.
  std::vector<double> no_depth(s.px.size(), 0.0);
  EXPECT_EQ(count_moved(check.static_candidates(s.prev, s.cur, geo::SE3(), s.px, no_depth), 0, s.px.size()),
            0u);
}

TEST(NewPointMotionCheck, MismatchedInputIsAnError) {
  const Scene s = make_scene(0.0);
  const NewPointMotionCheck check(on(2.0), camera());
  std::vector<double> short_depth(s.px.size() - 1, kWall);
  EXPECT_THROW((void)check.static_candidates(s.prev, s.cur, step_right(), s.px, short_depth), Error);
}

}  // namespace
}  // namespace sp::track
