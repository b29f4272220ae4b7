// Map ids and MapView::merge_map (the Atlas): a second map's keyframes and points move by the given
// transform into the first map's frame, are relabelled, and hang under the link keyframe.
#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "stillpoint/map/map.hpp"

namespace sp::map {
namespace {

KeyframeId add_keyframe(MapView& v, MapId m, const geo::SE3& T_cw) {
  Keyframe kf;
  kf.map_id = m;
  kf.T_cw = T_cw;
  kf.features.descriptors = cv::Mat(4, 32, CV_8U, cv::Scalar(0));
  for (int i = 0; i < 4; ++i) {
    kf.features.keypoints.emplace_back(static_cast<float>(10 * i), 5.f, 31.f);
    kf.features.depth.push_back(2.f);
    kf.features.u_right.push_back(0.f);
  }
  return v.add_keyframe(std::move(kf));
}

PointId add_point(MapView& v, KeyframeId kf, int feature, const Eigen::Vector3d& p_w) {
  MapPoint p;
  p.position = p_w;
  p.descriptor = cv::Mat(1, 32, CV_8U, cv::Scalar(feature));
  p.reference = p.first_keyframe = kf;
  const PointId id = v.add_point(std::move(p));
  v.add_observation(id, kf, feature);
  return id;
}

TEST(MapMerge, MovesRelabelsAndLinksTheNewerMap) {
  Map map;
  MapView v = map.view();
  const geo::SE3 truth_a(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.1, 0, 0));
  const KeyframeId a0 = add_keyframe(v, kFirstMap, geo::SE3());
  const KeyframeId a1 = add_keyframe(v, kFirstMap, truth_a);
  const PointId pa = add_point(v, a0, 0, {0, 0, 2});
  // Map 1 was started in its own frame: S maps it into map 0's.
  const geo::SE3 S(Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitY())),
                   Eigen::Vector3d(1, 2, 3));
  const geo::SE3 T_b0_true(Eigen::Quaterniond(Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitX())),
                           Eigen::Vector3d(-0.5, 0, 0));  // in map 0's frame
  const geo::SE3 T_b1_true(Eigen::Quaterniond::Identity(), Eigen::Vector3d(-0.7, 0.1, 0));
  const KeyframeId b0 = add_keyframe(v, MapId{1}, T_b0_true * S);  // as map 1 holds it
  const KeyframeId b1 = add_keyframe(v, MapId{1}, T_b1_true * S);
  const Eigen::Vector3d pb_true(0.4, -0.2, 2.5);
  const PointId pb = add_point(v, b1, 1, S.inverse() * pb_true);
  v.keyframe(b1)->parent = b0;
  v.keyframe(b0)->children.insert(b1);

  EXPECT_EQ(v.live_maps(), (std::vector<MapId>{kFirstMap, MapId{1}}));
  EXPECT_EQ(v.map_root(MapId{1}), b0);
  EXPECT_EQ(v.map_root(kFirstMap), a0);
  EXPECT_EQ(v.live_keyframes(MapId{1}), 2u);

  EXPECT_EQ(v.merge_map(MapId{1}, kFirstMap, S, b1, a1), 2u);
  EXPECT_EQ(v.live_maps(), std::vector<MapId>{kFirstMap});
  EXPECT_EQ(v.live_keyframes(kFirstMap), 4u);
  EXPECT_EQ(v.map_root(kFirstMap), a0);
  for (const auto& [kid, T] : {std::pair{b0, T_b0_true}, std::pair{b1, T_b1_true}}) {
    EXPECT_EQ(v.keyframe(kid)->map_id, kFirstMap);
    EXPECT_LT((v.keyframe(kid)->T_cw.matrix() - T.matrix()).norm(), 1e-12) << kid;
  }
  EXPECT_LT((v.point(pb)->position - pb_true).norm(), 1e-12);
  EXPECT_EQ(v.point(pa)->position, Eigen::Vector3d(0, 0, 2));  // map 0 does not move
  EXPECT_EQ(v.keyframe(a0)->T_cw.translation(), Eigen::Vector3d::Zero());
  // The old root hangs under the link keyframe; the two link keyframes share a loop edge.
  EXPECT_EQ(v.keyframe(b0)->parent, a1);
  EXPECT_TRUE(v.keyframe(a1)->children.contains(b0));
  EXPECT_TRUE(v.keyframe(b1)->loop_edges.contains(a1));
  EXPECT_TRUE(v.keyframe(a1)->loop_edges.contains(b1));
}

}  // namespace
}  // namespace sp::map
