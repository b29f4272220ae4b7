// Purging retired records: culled points and keyframes are freed only after their grace period,
// replaced points redirect until then, and a slimmed keyframe keeps what the trajectory follows.
#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "stillpoint/map/map.hpp"

namespace sp::map {
namespace {

Keyframe keyframe_with_features(std::size_t frame, int n, const geo::SE3& T_cw) {
  Keyframe kf;
  kf.frame_index = frame;
  kf.T_cw = T_cw;
  kf.features.descriptors = cv::Mat(n, 32, CV_8U, cv::Scalar(static_cast<int>(frame)));
  for (int i = 0; i < n; ++i) {
    kf.features.keypoints.emplace_back(static_cast<float>(10 * i), static_cast<float>(5 * i), 31.f);
    kf.features.depth.push_back(1.5f);
    kf.features.u_right.push_back(static_cast<float>(10 * i) - 20.f);
  }
  kf.index = make_feature_grid(kf.features.keypoints, 640, 480);
  kf.thumbnail = cv::Mat(24, 32, CV_8UC3, cv::Scalar(1, 2, 3));
  return kf;
}

PointId point_seen_by(MapView& v, const std::vector<KeyframeId>& kfs, int feature) {
  MapPoint p;
  p.position = {0.1 * feature, 0.0, 2.0};
  p.descriptor = cv::Mat(1, 32, CV_8U, cv::Scalar(feature));
  const PointId id = v.add_point(std::move(p));
  for (KeyframeId k : kfs) v.add_observation(id, k, feature);
  return id;
}

struct Fixture {
  Map map;
  std::vector<KeyframeId> kfs;
  PointId erased = kNoPoint, replaced = kNoPoint, survivor = kNoPoint, kept = kNoPoint;
  KeyframeId culled = kNoKeyframe;

  Fixture() {
    MapView v = map.view();
    for (int k = 0; k < 3; ++k) {
      const geo::SE3 T(Eigen::Quaterniond(Eigen::AngleAxisd(0.05 * k, Eigen::Vector3d::UnitY())),
                       Eigen::Vector3d(0.1 * k, 0.0, 0.0));
      kfs.push_back(v.add_keyframe(keyframe_with_features(static_cast<std::size_t>(k), 40, T)));
    }
    for (int i = 0; i < 30; ++i) point_seen_by(v, kfs, i);  // enough shared points for covisibility
    erased = point_seen_by(v, {kfs[0], kfs[1]}, 30);
    replaced = point_seen_by(v, {kfs[0]}, 31);
    survivor = point_seen_by(v, {kfs[1], kfs[2]}, 32);
    kept = point_seen_by(v, {kfs[0], kfs[2]}, 33);
    for (KeyframeId k : kfs) v.update_connections(k);
    v.erase_point(erased);
    v.replace_point(replaced, survivor);
    culled = kfs[1];
    v.erase_keyframe(culled);
  }
};

TEST(MapPurge, RetirementIsStampedWithTheNextKeyframeId) {
  Fixture f;
  MapView v = f.map.view();
  const KeyframeId next = v.next_ids().first;
  EXPECT_EQ(v.point(f.erased)->retired_at, next);
  EXPECT_EQ(v.point(f.replaced)->retired_at, next);
  EXPECT_EQ(v.keyframe(f.culled)->retired_at, next);
  EXPECT_EQ(v.point(f.kept)->retired_at, kNoKeyframe);
  EXPECT_EQ(v.keyframe(f.kfs[0])->retired_at, kNoKeyframe);
}

TEST(MapPurge, NothingIsFreedWithinTheGracePeriod) {
  Fixture f;
  MapView v = f.map.view();
  const KeyframeId next = v.next_ids().first;
  EXPECT_EQ(v.purge_bad(next), 0U);  // retired at `next`, not before it
  ASSERT_NE(v.point(f.erased), nullptr);
  ASSERT_NE(v.point(f.replaced), nullptr);
  EXPECT_EQ(v.live_point(f.replaced), v.point(f.survivor));  // still redirects
  EXPECT_FALSE(v.keyframe(f.culled)->features.descriptors.empty());
}

TEST(MapPurge, RetiredPointsGoAndCulledKeyframesShrinkToTheirTreeLink) {
  Fixture f;
  MapView v = f.map.view();
  const std::size_t points_before = v.points().size();
  const Keyframe before = *v.keyframe(f.culled);
  EXPECT_EQ(v.purge_bad(KeyframeId{v.next_ids().first.value() + 1}), 3U);  // two points, one keyframe
  EXPECT_EQ(v.points().size(), points_before - 2);
  EXPECT_EQ(v.point(f.erased), nullptr);
  EXPECT_EQ(v.point(f.replaced), nullptr);
  EXPECT_EQ(v.live_point(f.replaced), nullptr);  // a stale id now resolves to nothing, like any erased one
  EXPECT_NE(v.live_point(f.survivor), nullptr);
  EXPECT_NE(v.live_point(f.kept), nullptr);

  const Keyframe* slim = v.keyframe(f.culled);
  ASSERT_NE(slim, nullptr);
  EXPECT_TRUE(slim->bad);
  EXPECT_EQ(slim->features.size(), 0U);
  EXPECT_TRUE(slim->features.descriptors.empty());
  EXPECT_TRUE(slim->points.empty());
  EXPECT_TRUE(slim->thumbnail.empty());
  // What frames that referenced it need: the pose, its parent and the pose relative to the parent.
  EXPECT_EQ(slim->parent, before.parent);
  EXPECT_EQ(slim->frame_index, before.frame_index);
  EXPECT_LT((slim->T_c_parent.matrix() - before.T_c_parent.matrix()).norm(), 1e-15);
  EXPECT_LT((slim->T_cw.matrix() - before.T_cw.matrix()).norm(), 1e-15);
  // Live keyframes are untouched.
  EXPECT_EQ(v.keyframe(f.kfs[0])->features.size(), 40U);
  EXPECT_FALSE(v.keyframe(f.kfs[2])->thumbnail.empty());
  EXPECT_EQ(v.live_keyframes(), 2U);
}

TEST(MapPurge, PurgingTwiceFreesNothingMore) {
  Fixture f;
  MapView v = f.map.view();
  const KeyframeId later{v.next_ids().first.value() + 5};
  EXPECT_EQ(v.purge_bad(later), 3U);
  EXPECT_EQ(v.purge_bad(later), 0U);
}

}  // namespace
}  // namespace sp::map
