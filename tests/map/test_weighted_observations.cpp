// ORB-SLAM's observation count for RGB-D: a keyframe that has depth at the feature counts twice (the
// depth reading is a second view), one without depth once; "tracked points" of a keyframe use it.
#include <gtest/gtest.h>

#include "stillpoint/map/map.hpp"

namespace sp::map {
namespace {

Keyframe keyframe(int n, bool with_depth) {
  Keyframe kf;
  kf.features.descriptors = cv::Mat(n, 32, CV_8U, cv::Scalar(0));
  for (int i = 0; i < n; ++i) {
    kf.features.keypoints.emplace_back(static_cast<float>(10 * i), 20.f, 31.f);
    kf.features.depth.push_back(with_depth ? 2.0f : -1.f);
    kf.features.u_right.push_back(with_depth ? static_cast<float>(100 + 10 * i) - 20.f : -1.f);
  }
  kf.index = make_feature_grid(kf.features.keypoints, 640, 480);
  return kf;
}

PointId point(MapView& v, const std::vector<KeyframeId>& seen_by, int feature) {
  MapPoint p;
  p.descriptor = cv::Mat(1, 32, CV_8U, cv::Scalar(0));
  const PointId id = v.add_point(std::move(p));
  for (KeyframeId k : seen_by) v.add_observation(id, k, feature);
  return id;
}

TEST(WeightedObservations, DepthObservationsCountTwice) {
  Map map;
  MapView v = map.view();
  const KeyframeId d1 = v.add_keyframe(keyframe(4, true));
  const KeyframeId d2 = v.add_keyframe(keyframe(4, true));
  const KeyframeId m1 = v.add_keyframe(keyframe(4, false));
  const KeyframeId m2 = v.add_keyframe(keyframe(4, false));
  EXPECT_EQ(v.weighted_observations(*v.point(point(v, {d1}, 0))), 2);
  EXPECT_EQ(v.weighted_observations(*v.point(point(v, {d1, m1}, 1))), 3);
  EXPECT_EQ(v.weighted_observations(*v.point(point(v, {m1, m2}, 2))), 2);
  EXPECT_EQ(v.weighted_observations(*v.point(point(v, {d1, d2}, 3))), 4);
  // d1 sees points 0 (2), 1 (3), 3 (4): two of them reach 3 weighted observations, one reaches 4.
  EXPECT_EQ(v.tracked_points(d1, 3), 2);
  EXPECT_EQ(v.tracked_points(d1, 4), 1);
  EXPECT_EQ(v.tracked_points(m2, 2), 1);
  EXPECT_EQ(v.tracked_points(m2, 3), 0);
}

}  // namespace
}  // namespace sp::map
