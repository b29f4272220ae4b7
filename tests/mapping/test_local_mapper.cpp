// The local mapper's rules on generated keyframe sets (tests/support/synthetic_map.hpp: exact projections
// of points with unique descriptors, depth for every point nearer than a limit): keyframe culling
// (a keyframe whose close points at least three others see is redundant; the root, keyframes with only
// far points and keyframes held by loop closing stay), culling of new points nobody sees again, and
// two-view triangulation of features without depth.
#include <gtest/gtest.h>

#include "../support/synthetic_map.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/map/keyframe_hold.hpp"
#include "stillpoint/mapping/local_mapper.hpp"

namespace sp::mapping {
namespace {

// A camera at (x, 0, 0) looking down +z.
geo::SE3 at(double x) { return testing::camera_pose(Eigen::Vector3d(x, 0, 0), 0.0); }

class LocalMapperTest : public ::testing::Test {
 protected:
  LocalMapper make_mapper(bool triangulate = false) {
    LocalMappingConfig c;
    c.local_ba = false;  // the rules under test, not the optimiser
    c.triangulation.enabled = triangulate;
    return LocalMapper(map_, c, cam_, depth_, pyramid_);
  }
  // n keyframes a centimetre apart, all seeing the same points of the scene.
  std::vector<map::KeyframeId> build(const testing::SyntheticScene& scene, int n,
                                     double depth_limit = 100.0) {
    testing::SyntheticMapBuilder builder(map_, scene, cam_, depth_.bf, 100, depth_limit);
    for (int k = 0; k < n; ++k) builder.add(at(0.01 * k), at(0.01 * k));
    builder.finish(pyramid_);
    return builder.keyframes();
  }
  bool culled(map::KeyframeId k) {
    map::MapView view = map_.view();
    return view.keyframe(k)->bad;
  }

  map::Map map_;
  geo::CameraIntrinsics cam_;
  track::DepthModel depth_;  // close_depth 3.2 m
  map::ScalePyramid pyramid_ = map::ScalePyramid::make(8, 1.2);
};

TEST_F(LocalMapperTest, CullsRedundantKeyframesDownToThreeWitnessesButNeverTheRoot) {
  const auto scene = testing::make_slab_scene(600, 1.0, 0.8, 1.5, 3.0, 11);  // all close points
  const auto ids = build(scene, 6);
  const LocalMappingStats s = make_mapper().process(ids.back());
  // Every point is seen by all six keyframes. Each of the new keyframe's covisibles but the root is
  // redundant while its points have >= 3 other witnesses: three of the four go, whatever the order,
  // and the last one's points are left with two (the root and the new keyframe).
  EXPECT_EQ(s.culled_keyframes, 3);
  EXPECT_FALSE(culled(ids.front()));
  EXPECT_FALSE(culled(ids.back()));
  map::MapView view = map_.view();
  EXPECT_EQ(view.live_keyframes(), 3u);
}

TEST_F(LocalMapperTest, KeepsKeyframesWhosePointsFewerThanThreeOthersSee) {
  const auto scene = testing::make_slab_scene(600, 1.0, 0.8, 1.5, 3.0, 11);
  const auto ids = build(scene, 3);
  EXPECT_EQ(make_mapper().process(ids.back()).culled_keyframes, 0);
}

TEST_F(LocalMapperTest, OnlyClosePointsMakeAKeyframeRedundant) {
  // Beyond close_depth (3.2 m) an RGB-D point is not reliable enough to vouch for redundancy.
  const auto scene = testing::make_slab_scene(600, 2.0, 1.5, 3.5, 5.0, 11);
  const auto ids = build(scene, 6);
  EXPECT_EQ(make_mapper().process(ids.back()).culled_keyframes, 0);
}

TEST_F(LocalMapperTest, KeyframesHeldByLoopClosingAreNotCulledUntilReleased) {
  const auto scene = testing::make_slab_scene(600, 1.0, 0.8, 1.5, 3.0, 11);
  const auto ids = build(scene, 6);
  map::KeyframeHold hold(map_);
  {
    map::MapView view = map_.view();
    for (std::size_t k = 1; k + 1 < ids.size(); ++k) ASSERT_TRUE(hold.add(view, ids[k]));
  }
  LocalMapper mapper = make_mapper();
  // The same map as above, where three of these four keyframes are culled: held, none is.
  EXPECT_EQ(mapper.process(ids.back()).culled_keyframes, 0);
  for (map::KeyframeId k : ids) EXPECT_FALSE(culled(k));
  {
    map::MapView view = map_.view();
    hold.release(view);
    EXPECT_EQ(view.keyframe(ids[1])->culling_holds, 0);
  }
  // Released, the rules apply again.
  EXPECT_EQ(mapper.process(ids.back()).culled_keyframes, 3);
}

TEST_F(LocalMapperTest, HoldsNestAndRefuseCulledKeyframes) {
  const auto scene = testing::make_slab_scene(300, 1.0, 0.8, 1.5, 3.0, 11);
  const auto ids = build(scene, 3);
  map::MapView view = map_.view();
  ASSERT_TRUE(view.hold_keyframe(ids[1]));
  ASSERT_TRUE(view.hold_keyframe(ids[1]));
  view.release_keyframe(ids[1]);
  EXPECT_FALSE(view.erase_keyframe(ids[1]));  // one hold left
  view.release_keyframe(ids[1]);
  EXPECT_TRUE(view.erase_keyframe(ids[1]));
  EXPECT_FALSE(view.hold_keyframe(ids[1]));  // culled: nothing to hold
  EXPECT_THROW(view.release_keyframe(ids[2]), Error);
}

TEST_F(LocalMapperTest, NewPointsNobodySeesAgainAreCulledTwoKeyframesLater) {
  // Keyframe 1 at x = 0, keyframes 2 and 3 at x = 0.6 m: the left part of what keyframe 1 sees is out
  // of their view. Its points there have one depth view (weighted 2 < 3) and go two keyframes later.
  const auto scene = testing::make_slab_scene(800, 1.5, 0.8, 1.5, 3.0, 13);
  testing::SyntheticMapBuilder builder(map_, scene, cam_, depth_.bf, 100);
  builder.add(at(0.0), at(0.0));
  builder.add(at(0.6), at(0.6));
  builder.add(at(0.61), at(0.61));
  builder.finish(pyramid_);
  const auto& ids = builder.keyframes();
  std::vector<map::PointId> alone, shared;
  {
    map::MapView view = map_.view();
    for (map::PointId pid : view.keyframe(ids[0])->points) {
      if (pid == map::kNoPoint) continue;
      (view.point(pid)->observations.size() == 1 ? alone : shared).push_back(pid);
    }
  }
  ASSERT_GT(alone.size(), 30u);
  ASSERT_GT(shared.size(), 30u);
  LocalMapper mapper = make_mapper();
  mapper.process(ids[0]);
  mapper.process(ids[1]);
  {
    map::MapView view = map_.view();
    for (map::PointId pid : alone) EXPECT_FALSE(view.point(pid)->bad) << "culled before its time";
  }
  const LocalMappingStats s = mapper.process(ids[2]);
  EXPECT_EQ(s.culled_points, static_cast<int>(alone.size()));
  map::MapView view = map_.view();
  for (map::PointId pid : alone) EXPECT_TRUE(view.point(pid)->bad);
  for (map::PointId pid : shared) EXPECT_FALSE(view.point(pid)->bad);
}

TEST_F(LocalMapperTest, TriangulatesFeaturesWithoutDepthAtTheirTruePositions) {
  // Depth readings end at 3 m; points from 3 to 6 m are seen without depth by two keyframes 0.3 m
  // apart (parallax 3-6 degrees), so only triangulation can map them.
  const auto scene = testing::make_slab_scene(800, 2.5, 1.5, 1.5, 6.0, 17);
  testing::SyntheticMapBuilder builder(map_, scene, cam_, depth_.bf, 100, 3.0);
  builder.add(at(0.0), at(0.0));
  builder.add(at(0.3), at(0.3));
  builder.finish(pyramid_);
  const auto& ids = builder.keyframes();
  std::size_t before = 0;
  {
    map::MapView view = map_.view();
    before = view.live_points();
  }
  LocalMapper mapper = make_mapper(true);
  const LocalMappingStats s = mapper.process(ids[1]);
  ASSERT_GT(s.triangulated_points, 50);
  map::MapView view = map_.view();
  EXPECT_EQ(view.live_points(), before + static_cast<std::size_t>(s.triangulated_points));
  // Each new point lies on its scene point: both views are exact, so the error is the solver's.
  int checked = 0;
  for (const auto& [pid, p] : view.points()) {
    if (p.bad || p.first_keyframe != ids[1] || p.observations.size() != 2) continue;
    const int f = p.observations.at(ids[1]);
    const Eigen::Vector3d p_c = view.keyframe(ids[1])->T_cw * p.position;
    const auto& kp = view.keyframe(ids[1])->features.keypoints[static_cast<std::size_t>(f)];
    // The descriptor names the scene point (unique random rows).
    int row = -1;
    for (int r = 0; r < scene.descriptors.rows && row < 0; ++r)
      if (cv::norm(scene.descriptors.row(r), view.keyframe(ids[1])->features.descriptors.row(f),
                   cv::NORM_HAMMING) == 0)
        row = r;
    ASSERT_GE(row, 0);
    EXPECT_LT((p.position - scene.points[static_cast<std::size_t>(row)]).norm(), 0.01);
    EXPECT_GT(p_c.z(), 3.0);  // only features without depth were triangulated
    EXPECT_NEAR(cam_.project(p_c).x(), kp.pt.x, 0.01);
    ++checked;
  }
  EXPECT_EQ(checked, s.triangulated_points);
}

// Keyframe 0 at the origin, keyframe 1 seeing the scene from x = 1 cm but stored at 7 cm (a tracked pose
// 6 cm off); one local BA at keyframe 1 with `config` (culling and triangulation off). Returns the BA's
// stats and where keyframe 1's centre ends up (x).
struct OffsetKeyframeBA {
  LocalMappingStats stats;
  double x = 0;
};
OffsetKeyframeBA ba_of_offset_keyframe(const testing::SyntheticScene& scene, LocalMappingConfig config,
                                       const geo::CameraIntrinsics& cam, const track::DepthModel& depth,
                                       const map::ScalePyramid& pyramid) {
  map::Map map;
  testing::SyntheticMapBuilder builder(map, scene, cam, depth.bf, 100);
  builder.add(at(0.0), at(0.0));
  builder.add(at(0.01), at(0.07));
  builder.finish(pyramid);
  config.cull_keyframes = false;
  config.triangulation.enabled = false;
  LocalMapper mapper(map, config, cam, depth, pyramid);
  OffsetKeyframeBA out;
  out.stats = mapper.process(builder.keyframes()[1]);
  map::MapView view = map.view();
  out.x = view.keyframe(builder.keyframes()[1])->T_cw.inverse().translation().x();
  return out;
}

// A local BA that would carry a keyframe further than ba_max_keyframe_move_m is dropped: keyframe 1 is
// stored 6 cm from where it saw the scene (its views are exact), so BA moves it back 6 cm. With the
// bound at 3 cm nothing changes; without it, BA puts the keyframe where it was.
TEST_F(LocalMapperTest, ALocalBAThatMovesAKeyframeTooFarIsDropped) {
  const auto scene = testing::make_slab_scene(600, 1.5, 1.0, 1.5, 3.0, 21);
  for (const double bound : {0.03, 0.0, 0.1}) {
    LocalMappingConfig c;
    c.ba_max_keyframe_move_m = bound;
    const auto [s, x] = ba_of_offset_keyframe(scene, c, cam_, depth_, pyramid_);
    const bool dropped = bound > 0.0 && bound < 0.06;
    EXPECT_EQ(s.ba_dropped, dropped) << "bound " << bound;
    EXPECT_TRUE(s.ba_solved) << "bound " << bound;
    // BA pulls keyframe 1 from its 7 cm start back to the scene's 1 cm: a 6 cm move, bound or not.
    EXPECT_NEAR(s.ba_largest_keyframe_move_m, 0.06, 0.005) << "bound " << bound;
    if (dropped) {
      EXPECT_DOUBLE_EQ(x, 0.07) << "bound " << bound;
    } else {
      EXPECT_NEAR(x, 0.01, 0.005) << "bound " << bound;
    }
  }
}

TEST_F(LocalMapperTest, AKeyframeWhoseSharedPointsCrowdIntoAPatchKeepsItsTrackedPose) {
  // BA refines keyframe 1 back unless its shared points, all in a small patch of the image, leave its
  // centre loosely pinned; then the weak-keyframe rule holds it where tracking put it.
  struct Case {
    double half_width;  // m, of the slab of points 1.5-3 m away
    double bound;       // m, ba_weak_keyframe_std_m
    bool held;
  };
  for (const Case c : {Case{1.5, 0.01, false}, Case{0.04, 0.01, true}, Case{0.04, 0.0, false}}) {
    const auto scene = testing::make_slab_scene(300, c.half_width, c.half_width, 1.5, 3.0, 5);
    LocalMappingConfig config;
    config.ba_weak_keyframe_std_m = c.bound;
    const auto [s, x] = ba_of_offset_keyframe(scene, config, cam_, depth_, pyramid_);
    const std::string label =
        "half width " + std::to_string(c.half_width) + ", bound " + std::to_string(c.bound);
    EXPECT_EQ(s.ba_held_keyframes, c.held ? 1 : 0) << label;
    if (c.held) {
      EXPECT_DOUBLE_EQ(x, 0.07) << label;
    } else {
      EXPECT_NEAR(x, 0.01, 0.005) << label;
    }
  }
}

}  // namespace
}  // namespace sp::mapping
