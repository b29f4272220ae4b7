// The tracker on generated frames (tests/support/synthetic_map.hpp: exact projections of points with
// unique descriptors, depth for each): it must recover known camera poses, against its own map along
// a turning path and against a map it is given, where the first frame has to be found by
// relocalisation. Exact data, so the bounds are the solver's tolerance, far below a pixel's worth.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>

#include "../support/synthetic_frame.hpp"
#include "stillpoint/tracking/tracker.hpp"

namespace sp::track {
namespace {

// Walks along x and turns about y: 1 cm and 0.3 degrees a frame.
geo::SE3 path_pose(std::size_t i) {
  const double s = static_cast<double>(i);
  return testing::camera_pose(Eigen::Vector3d(0.01 * s, 0.0, 0.0), 0.3 * s * M_PI / 180.0);
}

class TrackerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    config_.keyframes.policy = "heuristic";
    scene_ = testing::make_slab_scene(1500, 2.5, 1.8, 2.0, 4.0, 3);
  }
  std::unique_ptr<Tracker> make_tracker() {
    return std::make_unique<Tracker>(map_, config_, cam_, depth_, pyramid_, 30.0);
  }
  // The written pose of a frame (camera to world), if any.
  std::optional<geo::SE3> written(const Tracker& t, std::size_t index) {
    map::MapView view = map_.view();
    for (const auto& p : t.trajectory().resolve(view))
      if (std::abs(p.stamp - static_cast<double>(index) / 30.0) < 1e-9) return p.T_wc;
    return std::nullopt;
  }

  map::Map map_;
  TrackerConfig config_;
  geo::CameraIntrinsics cam_;
  DepthModel depth_;
  map::ScalePyramid pyramid_ = map::ScalePyramid::make(8, 1.2);
  testing::SyntheticScene scene_;
};

TEST_F(TrackerTest, RecoversEveryPoseOfAKnownPath) {
  auto t = make_tracker();
  constexpr std::size_t kFrames = 60;
  for (std::size_t i = 0; i < kFrames; ++i) {
    Frame f = testing::synthetic_frame(scene_, path_pose(i), i, cam_, depth_.bf);
    ASSERT_EQ(t->track(f, {}).state, TrackingState::Ok) << "frame " << i;
  }
  // The first frame is the map's origin, as the path's: poses compare without alignment.
  for (std::size_t i = 0; i < kFrames; ++i) {
    const auto T_wc = written(*t, i);
    ASSERT_TRUE(T_wc.has_value()) << i;
    const PoseDeviation d = pose_deviation(T_wc->inverse(), path_pose(i));
    EXPECT_LT(d.translation_m, 1e-3) << "frame " << i;
    EXPECT_LT(d.rotation_deg, 0.02) << "frame " << i;
  }
  EXPECT_EQ(t->lost_frames(), 0u);
}

// ORB-SLAM3's RGB-D initialisation: the first keyframe makes a map point of every feature with a
// depth reading, far ones too; later keyframes only of the close ones (at least new_points_min). The
// slab spans 2-4 m around the 3.2 m close-depth limit, so the two rules must give different maps.
TEST_F(TrackerTest, TheFirstKeyframeMakesAPointOfEveryFeatureWithDepth) {
  const Frame probe = testing::synthetic_frame(scene_, path_pose(0), 0, cam_, depth_.bf);
  const auto with_depth = static_cast<std::size_t>(
      std::count_if(probe.features.depth.begin(), probe.features.depth.end(), [](float d) { return d > 0; }));
  const auto close =
      static_cast<std::size_t>(std::count_if(probe.features.depth.begin(), probe.features.depth.end(),
                                             [&](float d) { return d > 0 && d <= depth_.close_depth; }));
  ASSERT_GT(with_depth, close + 100) << "the scene must have far features for this test";
  ASSERT_GT(close, static_cast<std::size_t>(config_.new_points_min));

  for (const bool all : {true, false}) {
    map::Map map;
    config_.init_all_depth_points = all;
    Tracker t(map, config_, cam_, depth_, pyramid_, 30.0);
    Frame f = testing::synthetic_frame(scene_, path_pose(0), 0, cam_, depth_.bf);
    ASSERT_EQ(t.track(f, {}).state, TrackingState::Ok);
    map::MapView view = map.view();
    EXPECT_EQ(view.live_points(), all ? with_depth : close) << "init_all_depth_points " << all;
  }
}

TEST_F(TrackerTest, FindsItsPoseInAGivenMapAndTracksOn) {
  // A map of five keyframes along x, made outside the tracker; the camera starts between two of them.
  {
    testing::SyntheticMapBuilder builder(map_, scene_, cam_, depth_.bf, 100);
    for (int k = 0; k < 5; ++k) {
      const geo::SE3 T = testing::camera_pose(Eigen::Vector3d(0.1 * k, 0, 0), 0.0);
      builder.add(T, T);
    }
    builder.finish(pyramid_);
  }
  config_.relocalization_verify_frames = 0;  // the first pose is trusted at once
  auto t = make_tracker();
  t->start_in_existing_map();
  const auto truth = [](std::size_t i) {
    return testing::camera_pose(Eigen::Vector3d(0.23 + 0.01 * static_cast<double>(i), 0.02, 0.0), 0.01);
  };
  for (std::size_t i = 0; i < 10; ++i) {
    Frame f = testing::synthetic_frame(scene_, truth(i), i, cam_, depth_.bf);
    const TrackOutcome o = t->track(f, {});
    ASSERT_EQ(o.state, TrackingState::Ok) << "frame " << i;
    EXPECT_EQ(o.relocalized, i == 0) << "frame " << i;
  }
  for (std::size_t i = 0; i < 10; ++i) {
    const auto T_wc = written(*t, i);
    ASSERT_TRUE(T_wc.has_value()) << i;
    const PoseDeviation d = pose_deviation(T_wc->inverse(), truth(i));
    EXPECT_LT(d.translation_m, 1e-3) << "frame " << i;
    EXPECT_LT(d.rotation_deg, 0.02) << "frame " << i;
  }
}

TEST_F(TrackerTest, ASuddenStopIsTrackedAtTheTruePose) {
  // 2 cm a frame, then the camera stops dead: the constant-velocity guess is 2 cm off (about 5 px at
  // 2-4 m), which the tracker must absorb without losing the pose; a stop is a motion, not a jump, so
  // the motion model is kept (tracking.motion_break_m).
  auto t = make_tracker();
  const auto truth = [](std::size_t i) {
    return testing::camera_pose(
        Eigen::Vector3d(0.02 * static_cast<double>(std::min<std::size_t>(i, 15)), 0, 0), 0);
  };
  for (std::size_t i = 0; i < 20; ++i) {
    Frame f = testing::synthetic_frame(scene_, truth(i), i, cam_, depth_.bf);
    ASSERT_EQ(t->track(f, {}).state, TrackingState::Ok) << "frame " << i;
  }
  for (std::size_t i = 14; i < 20; ++i) {
    const auto T_wc = written(*t, i);
    ASSERT_TRUE(T_wc.has_value());
    EXPECT_LT(pose_deviation(T_wc->inverse(), truth(i)).translation_m, 1e-3) << "frame " << i;
  }
  EXPECT_EQ(t->motion_breaks(), 0u);
}

// Carried back: 1 cm a frame for 20 frames, then the camera is at the start again and stands still.
// The pose found there is 20 cm from the constant-velocity guess: a jump, not a motion, so it must
// not become the velocity (the next frame would be predicted 20 cm further on). A stop (2 cm off the
// guess) is a motion and keeps it.
TEST_F(TrackerTest, AJumpIsNotTakenAsTheNextFramesMotion) {
  auto t = make_tracker();
  constexpr std::size_t kWalk = 20;
  const auto truth = [](std::size_t i) {
    return testing::camera_pose(Eigen::Vector3d(i < kWalk ? 0.01 * static_cast<double>(i) : 0.0, 0, 0), 0);
  };
  for (std::size_t i = 0; i < kWalk + 5; ++i) {
    Frame f = testing::synthetic_frame(scene_, truth(i), i, cam_, depth_.bf);
    ASSERT_EQ(t->track(f, {}).state, TrackingState::Ok) << "frame " << i;
    if (i == kWalk) {
      EXPECT_FALSE(t->predicted_motion().has_value()) << "the jump became the velocity";
    } else if (i > 0) {
      ASSERT_TRUE(t->predicted_motion().has_value()) << "frame " << i;
    }
  }
  EXPECT_EQ(t->motion_breaks(), 1u);
  for (std::size_t i = kWalk; i < kWalk + 5; ++i) {
    const auto T_wc = written(*t, i);
    ASSERT_TRUE(T_wc.has_value()) << i;
    EXPECT_LT(pose_deviation(T_wc->inverse(), truth(i)).translation_m, 1e-3) << "frame " << i;
  }
}

// Moves the features left of x_person (a person proven still, culled) from the frame's features to
// its reserve, as the front end does with dynamic.motion.reserve_still_people.
void cull_person(Frame& f, float x_person) {
  map::FeatureSet kept, person;
  std::vector<int> kept_rows, person_rows;
  for (std::size_t i = 0; i < f.features.size(); ++i) {
    const bool on_person = f.features.keypoints[i].pt.x < x_person;
    map::FeatureSet& to = on_person ? person : kept;
    to.keypoints.push_back(f.features.keypoints[i]);
    to.depth.push_back(f.features.depth[i]);
    to.u_right.push_back(f.features.u_right[i]);
    (on_person ? person_rows : kept_rows).push_back(static_cast<int>(i));
  }
  const auto rows_of = [&](const std::vector<int>& rows) {
    cv::Mat d(static_cast<int>(rows.size()), 32, CV_8U);
    for (std::size_t r = 0; r < rows.size(); ++r)
      f.features.descriptors.row(rows[r]).copyTo(d.row(static_cast<int>(r)));
    return d;
  };
  kept.descriptors = rows_of(kept_rows);
  person.descriptors = rows_of(person_rows);
  f.culled = person.size();
  f.features = std::move(kept);
  f.reserve = std::move(person);
}

// The last resort (docs/dynamic.md, "A last resort is never mapped"): a person proven still fills
// most of the view and is culled; while the rest of the image suffices, keyframes keep the person's
// features aside. When the rest no longer holds the pose (a sliver at the image's edge, under
// min_inliers features), the frame is tracked again with the person, whose features the keyframes
// kept are mapped first: every frame keeps an exact pose. Without the retry those frames are lost.
TEST_F(TrackerTest, AFrameLostWithoutAStillPersonIsTrackedAgainWithIt) {
  const auto frame_at = [&](std::size_t i) {
    Frame f = testing::synthetic_frame(scene_, path_pose(i), i, cam_, depth_.bf);
    if (i >= 10) cull_person(f, i < 20 ? 320.f : 610.f);  // half the view, then all but a sliver
    return f;
  };
  ASSERT_LT(frame_at(20).features.size(), static_cast<std::size_t>(config_.min_inliers));
  for (const bool retry : {true, false}) {
    map::Map map;
    config_.still_people_retry = retry;
    Tracker t(map, config_, cam_, depth_, pyramid_, 30.0);
    std::size_t lost = 0;
    for (std::size_t i = 0; i < 30; ++i) {
      Frame f = frame_at(i);
      lost += t.track(f, {}).state == TrackingState::Ok ? 0 : 1;
    }
    if (!retry) {
      EXPECT_GT(lost, 0u) << "the sliver alone must not hold the pose, or this test proves nothing";
      continue;
    }
    EXPECT_EQ(lost, 0u);
    EXPECT_GE(t.reserve_stats().tracker_releases, 1u);
    EXPECT_EQ(t.reserve_stats().tracker_releases_tracked, t.reserve_stats().tracker_releases);
    EXPECT_GT(t.reserve_stats().points, 0u) << "no keyframe between frames 10 and 19 kept the person";
    map::MapView view = map.view();
    for (std::size_t i = 20; i < 30; ++i) {
      std::optional<geo::SE3> T_wc;
      for (const auto& p : t.trajectory().resolve(view))
        if (std::abs(p.stamp - static_cast<double>(i) / 30.0) < 1e-9) T_wc = p.T_wc;
      ASSERT_TRUE(T_wc.has_value()) << "frame " << i;
      const PoseDeviation d = pose_deviation(T_wc->inverse(), path_pose(i));
      EXPECT_LT(d.translation_m, 1e-3) << "frame " << i;
      EXPECT_LT(d.rotation_deg, 0.02) << "frame " << i;
    }
  }
}

TEST_F(TrackerTest, ReportsHowLongEachFrameHeldTheMapLock) {
  auto t = make_tracker();
  for (std::size_t i = 0; i < 10; ++i) {
    Frame f = testing::synthetic_frame(scene_, path_pose(i), i, cam_, depth_.bf);
    const auto start = std::chrono::steady_clock::now();
    ASSERT_EQ(t->track(f, {}).state, TrackingState::Ok) << "frame " << i;
    const double wall_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    // Every frame takes the lock at least once, and never for longer than the call took.
    EXPECT_GT(t->last_lock_ms(), 0.0) << "frame " << i;
    EXPECT_LE(t->last_lock_ms(), wall_ms) << "frame " << i;
  }
}

}  // namespace
}  // namespace sp::track
