// The tracker's copy of the map records a frame reads (LocalMapSnapshot) and the counters it writes
// back later (PointCounterUpdates): another stage may fuse or cull points between the two views, so
// copies resolve ids as MapReader::live_point does and the write-back skips what is gone.
#include <gtest/gtest.h>

#include "stillpoint/tracking/local_map_snapshot.hpp"

namespace sp::track {
namespace {

class LocalMapSnapshotTest : public ::testing::Test {
 protected:
  void SetUp() override {
    map::MapView view = map_.view();
    map::Keyframe kf;
    kf.T_cw = geo::SE3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.1, 0.2, 0.3));
    kf.features.keypoints.resize(3);
    kf.features.keypoints[2].angle = 45.f;
    kf.features.descriptors = cv::Mat(3, 32, CV_8U);
    for (int i = 0; i < 3; ++i) kf.features.descriptors.row(i).setTo(cv::Scalar(10 + i));
    kf.points.assign(3, map::kNoPoint);
    kf_ = view.add_keyframe(std::move(kf));
    for (int i = 0; i < 3; ++i) {
      map::MapPoint p;
      p.position = Eigen::Vector3d(i, 0, 2);
      p.descriptor = cv::Mat(1, 32, CV_8U, cv::Scalar(10 + i));
      p.max_distance = 3.0 + i;
      ids_.push_back(view.add_point(std::move(p)));
      view.add_observation(ids_.back(), kf_, i);
    }
  }

  map::Map map_;
  map::KeyframeId kf_ = map::kNoKeyframe;
  std::vector<map::PointId> ids_;
};

TEST_F(LocalMapSnapshotTest, CopiesFollowReplacementsAndAnswerUnderBothIds) {
  {
    map::MapView view = map_.view();
    view.replace_point(ids_[0], ids_[1]);  // local mapping fused point 0 into point 1
  }
  LocalMapSnapshot s;
  s.reset({kf_});
  {
    map::MapReader view = map_.reader();
    ASSERT_NE(s.add(view, ids_[0]), nullptr);
    ASSERT_NE(s.add(view, ids_[2]), nullptr);
    s.add_pose(view, kf_);
  }
  const LocalMapSnapshot::Point* p = s.live_point(ids_[0]);
  ASSERT_NE(p, nullptr);
  EXPECT_EQ(p->id, ids_[1]);
  EXPECT_EQ(s.live_point(ids_[1]), p);
  EXPECT_EQ(p->position, Eigen::Vector3d(1, 0, 2));
  EXPECT_EQ(p->descriptor[0], 11);
  EXPECT_EQ(p->max_distance, 4.0);
  EXPECT_EQ(s.anchor_feature(*p, kf_), 1);
  EXPECT_EQ(s.anchor_feature(*p, map::KeyframeId{kf_.value() + 1}), -1);  // not an anchor given to reset()
  EXPECT_EQ(s.size(), 2u);
  ASSERT_NE(s.pose(kf_), nullptr);
  EXPECT_EQ(s.pose(kf_)->T_cw.translation(), Eigen::Vector3d(0.1, 0.2, 0.3));
  EXPECT_EQ(s.pose(map::KeyframeId{kf_.value() + 1}), nullptr);
}

TEST_F(LocalMapSnapshotTest, APointCulledBetweenTwoReadsIsForgotten) {
  LocalMapSnapshot s;
  s.reset({});
  {
    map::MapReader view = map_.reader();
    ASSERT_NE(s.add(view, ids_[2]), nullptr);
  }
  {
    map::MapView view = map_.view();
    view.erase_point(ids_[2]);
  }
  map::MapReader view = map_.reader();
  EXPECT_EQ(s.add(view, ids_[2]), nullptr);
  EXPECT_EQ(s.live_point(ids_[2]), nullptr);
}

TEST_F(LocalMapSnapshotTest, AKeyframeCopyHoldsItsLivePointsAndAngles) {
  {
    map::MapView view = map_.view();
    view.erase_point(ids_[0]);
  }
  LocalMapSnapshot s;
  s.reset({});
  map::MapReader view = map_.reader();
  const auto kf = s.add_keyframe(view, kf_);
  ASSERT_TRUE(kf.has_value());
  EXPECT_FALSE(kf->bad);
  EXPECT_EQ(kf->points, (std::vector<map::PointId>{map::kNoPoint, ids_[1], ids_[2]}));
  EXPECT_EQ(kf->angles[2], 45.f);
  EXPECT_EQ(kf->descriptors.rows, 3);
  EXPECT_NE(s.live_point(ids_[2]), nullptr);
  EXPECT_FALSE(s.add_keyframe(view, map::KeyframeId{kf_.value() + 7}).has_value());
}

TEST_F(LocalMapSnapshotTest, CountersAreWrittenToThePointsStillAlive) {
  PointCounterUpdates counters;
  counters.visible(ids_[0]);
  counters.visible(ids_[1]);
  counters.found(ids_[1]);
  counters.visible(ids_[2]);
  map::MapView view = map_.view();
  view.replace_point(ids_[0], ids_[1]);  // fused meanwhile: its counters go to the survivor
  view.erase_point(ids_[2]);             // culled meanwhile: skipped
  const int visible_before = view.point(ids_[1])->visible;
  const int found_before = view.point(ids_[1])->found;
  counters.apply(view);
  EXPECT_EQ(view.point(ids_[1])->visible, visible_before + 2);
  EXPECT_EQ(view.point(ids_[1])->found, found_before + 1);
  // Applied once: a second apply adds nothing.
  counters.apply(view);
  EXPECT_EQ(view.point(ids_[1])->visible, visible_before + 2);
}

}  // namespace
}  // namespace sp::track
