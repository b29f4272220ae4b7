// New maps after a long loss and map merging (the Atlas, docs/robustness.md "New maps and merging"), on
// a small generated world: points with unique random descriptors, frames made of their exact
// projections, no images. The tracker maps one place, is carried to a place it never saw (no
// relocalisation possible), starts a new map there after the configured number of lost frames, and
// walks back; once a frame is found in the first map as well (and the next frames agree), the new map
// is moved into the first map's frame and merged.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <random>

#include "../support/synthetic_frame.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/map/map_file.hpp"
#include "stillpoint/tracking/tracker.hpp"

namespace sp::track {
namespace {

using World = testing::SyntheticScene;

// Points in x in [x0, x1), y in [-1.8, 1.8], z in [2, 4] ahead of a camera looking down +z.
void add_points(World& w, int n, double x0, double x1, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> x(x0, x1), y(-1.8, 1.8), z(2.0, 4.0);
  std::uniform_int_distribution<int> byte(0, 255);
  cv::Mat d(n, 32, CV_8U);
  for (int i = 0; i < n; ++i) {
    w.points.emplace_back(x(rng), y(rng), z(rng));
    for (int b = 0; b < 32; ++b) d.at<std::uint8_t>(i, b) = static_cast<std::uint8_t>(byte(rng));
  }
  if (w.descriptors.empty()) {
    w.descriptors = d;
  } else {
    cv::vconcat(w.descriptors, d, w.descriptors);
  }
}

geo::SE3 camera_at(double x) { return geo::SE3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(-x, 0, 0)); }

class Atlas : public ::testing::Test {
 protected:
  void SetUp() override {
    config_.keyframes.policy = "heuristic";
    config_.new_map_after_lost_frames = kLostBeforeNewMap;
    add_points(world_, 1500, -2.5, 2.5, 3);   // the first place
    add_points(world_, 3000, 2.5, 12.5, 11);  // the rest of the wall: never seen before the kidnap
  }
  std::unique_ptr<Tracker> make_tracker() { return make_tracker(map_); }
  std::unique_ptr<Tracker> make_tracker(map::Map& map) {
    return std::make_unique<Tracker>(map, config_, cam_, depth_, map::ScalePyramid::make(8, 1.2), 30.0);
  }
  TrackOutcome feed(Tracker& t, std::size_t index, double x) {
    truth_[index] = x;
    Frame f = testing::synthetic_frame(world_, camera_at(x), index, cam_, depth_.bf);
    return t.track(f, {});
  }

  // Frames 0..n-1 walk along the first place at 2 cm a frame, each expected tracked; returns n.
  std::size_t walk_first_place(Tracker& t, std::size_t n = 40) {
    for (std::size_t i = 0; i < n; ++i)
      EXPECT_EQ(feed(t, i, 0.02 * static_cast<double>(i)).state, TrackingState::Ok) << i;
    return n;
  }
  // A tracker on a map of its own (tests that run several configurations) that walked the first place
  // and was carried to x = 9 m, walking back 2 cm a frame, up to frame `until`: the next frame index
  // and position.
  struct Carried {
    std::unique_ptr<Tracker> tracker;
    std::size_t next = 0;
    double x = 0;
  };
  Carried carried_away(map::Map& map, std::size_t until) {
    Carried c{make_tracker(map)};
    c.next = walk_first_place(*c.tracker);
    for (c.x = 9.0; c.next < until; ++c.next, c.x -= 0.02) feed(*c.tracker, c.next, c.x);
    return c;
  }

  // carried_away() up to the frame after the one that started map 1: two maps open.
  Carried in_second_map(map::Map& map) {
    Carried c = carried_away(map, 41 + kLostBeforeNewMap);
    EXPECT_EQ(c.tracker->open_maps().size(), 2u);
    return c;
  }

  static constexpr int kLostBeforeNewMap = 10;
  map::Map map_;
  TrackerConfig config_;
  geo::CameraIntrinsics cam_;
  DepthModel depth_;
  World world_;
  std::map<std::size_t, double> truth_;  // frame index -> true camera x
};

TEST_F(Atlas, LostInAnUnmappedPlaceStartsANewMapThatMergesWhenTheOldMapIsSeenAgain) {
  auto t = make_tracker();
  std::size_t i = walk_first_place(*t);
  ASSERT_EQ(t->atlas_stats().maps_created, 1u);

  // Carried to x = 9 m: nothing of the first map in view, so relocalisation fails on every frame.
  double x = 9.0;
  for (; i < 40 + kLostBeforeNewMap; ++i, x -= 0.02) {
    const TrackOutcome o = feed(*t, i, x);
    ASSERT_EQ(o.state, TrackingState::Lost) << i;
    EXPECT_FALSE(o.relocalized) << i;
  }
  EXPECT_EQ(t->atlas_stats().maps_created, 1u);  // not before the configured number of lost frames
  const TrackOutcome started = feed(*t, i++, x);
  x -= 0.02;
  EXPECT_EQ(started.state, TrackingState::Ok);
  EXPECT_NE(started.new_keyframe, map::kNoKeyframe);
  EXPECT_EQ(t->atlas_stats().maps_created, 2u);
  EXPECT_EQ(t->current_map(), map::MapId{1});
  ASSERT_EQ(t->open_maps().size(), 2u);
  {
    map::MapReader view = map_.reader();
    EXPECT_EQ(view.keyframe(started.new_keyframe)->map_id, map::MapId{1});
    // Seeded at the last trusted pose (x = 0.78), not where the camera is.
    EXPECT_NEAR(view.keyframe(started.new_keyframe)->camera_center().x(), 0.78, 1e-3);
  }

  // Walking back towards the first place at 4 cm a frame, tracked in map 1, until the maps merge.
  std::size_t merged_at = 0;
  std::vector<map::KeyframeId> made_in_map1{started.new_keyframe};
  for (; x > 1.0; ++i, x -= 0.04) {
    const TrackOutcome o = feed(*t, i, x);
    ASSERT_EQ(o.state, TrackingState::Ok) << "frame " << i << " x " << x;
    if (merged_at == 0 && o.new_keyframe != map::kNoKeyframe) made_in_map1.push_back(o.new_keyframe);
    if (merged_at == 0 && t->atlas_stats().merges == 1) merged_at = i;
  }
  ASSERT_NE(merged_at, 0u) << "never merged";
  EXPECT_GT(truth_[merged_at], 2.0);  // merged as soon as enough of the first map was in view
  EXPECT_EQ(t->atlas_stats().merges, 1u);
  EXPECT_EQ(t->atlas_stats().merge_candidates, 1u);
  EXPECT_EQ(t->atlas_stats().merges_rejected, 0u);
  // While both maps were open a new search ran only every merge_search_interval-th frame (the frames
  // verifying the candidate are not new searches).
  const std::size_t open_frames = merged_at - (40 + kLostBeforeNewMap);
  ASSERT_GT(config_.merge_search_interval, 1);
  EXPECT_GE(t->atlas_stats().merge_searches, 1u);
  EXPECT_LE(t->atlas_stats().merge_searches,
            open_frames / static_cast<std::size_t>(config_.merge_search_interval) + 1);
  EXPECT_EQ(t->current_map(), map::kFirstMap);
  EXPECT_EQ(t->open_maps(), std::vector<map::MapId>{map::kFirstMap});
  EXPECT_EQ(t->lost_frames(), static_cast<std::size_t>(kLostBeforeNewMap));

  map::MapView view = map_.view();
  EXPECT_EQ(view.live_maps(), std::vector<map::MapId>{map::kFirstMap});
  double worst_m = 0, worst_deg = 0;
  for (map::KeyframeId k : made_in_map1) {
    const map::Keyframe* kf = view.keyframe(k);
    const PoseDeviation d = pose_deviation(kf->T_cw, camera_at(truth_.at(kf->frame_index)));
    worst_m = std::max(worst_m, d.translation_m);
    worst_deg = std::max(worst_deg, d.rotation_deg);
  }
  std::printf(
      "[ atlas    ] merged at frame %zu (camera at x = %.2f m), %zu keyframes of map 1, worst %.3f mm / %.4f "
      "deg\n",
      merged_at, truth_[merged_at], made_in_map1.size(), worst_m * 1000, worst_deg);
  // Every keyframe of the merged map now sits where the camera was, in the first map's frame.
  for (const auto& [kid, kf] : view.keyframes()) {
    EXPECT_EQ(kf.map_id, map::kFirstMap) << kid;
    const geo::SE3 truth = camera_at(truth_.at(kf.frame_index));
    const PoseDeviation d = pose_deviation(kf.T_cw, truth);
    EXPECT_LT(d.translation_m, 0.005) << "keyframe " << kid << " frame " << kf.frame_index;
    EXPECT_LT(d.rotation_deg, 0.1) << "keyframe " << kid;
  }
  EXPECT_GE(made_in_map1.size(), 3u);  // the new map's keyframes are among them
  for (map::KeyframeId k : made_in_map1) EXPECT_NE(view.keyframe(k), nullptr) << k;
  // And every written frame, the new map's included, resolves to its true place in map 0.
  const auto poses = t->trajectory().resolve(view);
  EXPECT_EQ(poses.size(), truth_.size() - static_cast<std::size_t>(kLostBeforeNewMap));
  for (const auto& p : poses) {
    const auto index = static_cast<std::size_t>(std::lround(p.stamp * 30.0));
    EXPECT_EQ(p.map_id, map::kFirstMap);
    EXPECT_NEAR(p.T_wc.translation().x(), truth_.at(index), 0.005) << index;
    EXPECT_NEAR(p.T_wc.translation().y(), 0.0, 0.005) << index;
    EXPECT_NEAR(p.T_wc.translation().z(), 0.0, 0.005) << index;
  }
}

TEST_F(Atlas, ZeroKeepsTheOldBehaviourLostStaysLost) {
  config_.new_map_after_lost_frames = 0;
  auto t = make_tracker();
  std::size_t i = walk_first_place(*t);
  double x = 9.0;
  for (; i < 100; ++i, x -= 0.02) EXPECT_EQ(feed(*t, i, x).state, TrackingState::Lost) << i;
  EXPECT_EQ(t->atlas_stats().maps_created, 1u);
  EXPECT_EQ(t->lost_frames(), 60u);
  EXPECT_EQ(t->open_maps().size(), 1u);
}

TEST_F(Atlas, NoNewMapFromAFrameWithTooFewDepthFeatures) {
  auto t = make_tracker();
  std::size_t i = walk_first_place(*t);
  // Lost twice as long as needed, but every frame keeps only 100 features (init_min_features is 200).
  for (; i < 40 + 2 * kLostBeforeNewMap; ++i) {
    Frame f = testing::synthetic_frame(world_, camera_at(9.0), i, cam_, depth_.bf);
    const int keep = 100;
    f.features.keypoints.resize(keep);
    f.features.depth.resize(keep);
    f.features.u_right.resize(keep);
    f.features.descriptors = f.features.descriptors.rowRange(0, keep).clone();
    f.extracted = keep;
    EXPECT_EQ(t->track(f, {}).state, TrackingState::Lost) << i;
  }
  EXPECT_EQ(t->atlas_stats().maps_created, 1u);
  // The first full frame starts the map at once.
  EXPECT_EQ(feed(*t, i, 9.0).state, TrackingState::Ok);
  EXPECT_EQ(t->atlas_stats().maps_created, 2u);
  EXPECT_EQ(t->current_map(), map::MapId{1});
}

// A map file written while two maps were open keeps them apart: on load both are open, and a frame
// relocalised in the second tracks in the second (its frame), not in a map 0 that mixes both.
TEST_F(Atlas, ASavedMapKeepsItsMapsApartWhenLoaded) {
  auto t = make_tracker();
  std::size_t i = walk_first_place(*t);
  double x = 9.0;
  for (; i < 40 + kLostBeforeNewMap + 20; ++i, x -= 0.02) feed(*t, i, x);
  ASSERT_EQ(t->open_maps().size(), 2u);
  ASSERT_EQ(t->current_map(), map::MapId{1});
  const auto file = std::filesystem::path(SP_TEST_TMP_DIR) / "atlas_two_maps.spmap";
  std::filesystem::create_directories(file.parent_path());
  map::MapFileInfo info;
  info.camera = cam_;
  map::save_map(map_, file, info);

  map::Map loaded;
  map::load_map(file, loaded);
  {
    map::MapReader a = map_.reader(), b = loaded.reader();
    EXPECT_EQ(b.live_maps().size(), 2u);
    for (map::KeyframeId k : a.keyframe_ids_sorted()) {
      ASSERT_NE(b.keyframe(k), nullptr) << k;
      EXPECT_EQ(b.keyframe(k)->map_id, a.keyframe(k)->map_id) << k;
    }
  }
  Tracker again(loaded, config_, cam_, depth_, map::ScalePyramid::make(8, 1.2), 30.0);
  again.start_in_existing_map();
  EXPECT_EQ(again.open_maps(), (std::vector<map::MapId>{map::kFirstMap, map::MapId{1}}));
  // Where map 1 was made: relocalised there, tracked in map 1.
  Frame f = testing::synthetic_frame(world_, camera_at(x + 0.02), 1000, cam_, depth_.bf);
  const TrackOutcome o = again.track(f, {});
  EXPECT_TRUE(o.relocalized);
  EXPECT_EQ(again.current_map(), map::MapId{1});
}

// tracking.young_map_frames: a map lost within that many frames of its start was begun in a view it
// cannot hold and is not worth waiting for (ORB-SLAM3 drops a lost map of < 10 keyframes); the first
// frame that fails to relocalise starts a new map.
TEST_F(Atlas, AMapLostSoonAfterItsStartIsFollowedByANewMapOnTheFirstFrameThatFailsToRelocalise) {
  config_.young_map_frames = 30;
  auto t = make_tracker();
  std::size_t i = walk_first_place(*t, 4);
  // Carried away: the first frame is lost, the next one fails to relocalise and starts map 1 at once.
  EXPECT_EQ(feed(*t, i++, 9.0).state, TrackingState::Lost);
  EXPECT_EQ(t->atlas_stats().maps_created, 1u);
  const TrackOutcome started = feed(*t, i++, 8.98);
  EXPECT_EQ(started.state, TrackingState::Ok);
  EXPECT_FALSE(started.relocalized);
  EXPECT_EQ(t->atlas_stats().maps_created, 2u);
  EXPECT_EQ(t->current_map(), map::MapId{1});
  EXPECT_EQ(t->lost_frames(), 1u);
}

TEST_F(Atlas, AMapLostLaterThanTheYoungSpanWaitsForTheConfiguredLoss) {
  config_.young_map_frames = 30;
  auto t = make_tracker();
  std::size_t i = walk_first_place(*t);
  double x = 9.0;
  for (; i < 40 + kLostBeforeNewMap; ++i, x -= 0.02)
    EXPECT_EQ(feed(*t, i, x).state, TrackingState::Lost) << i;
  EXPECT_EQ(t->atlas_stats().maps_created, 1u);
  EXPECT_EQ(feed(*t, i, x).state, TrackingState::Ok);
  EXPECT_EQ(t->atlas_stats().maps_created, 2u);
}

// tracking.merge_verify_misses: a check frame that finds nothing in the other map (its view of the first
// place hidden) does not reject the candidate when a miss is allowed; the merge then comes one frame
// later. Without misses allowed the candidate is rejected there.
TEST_F(Atlas, AMergeCheckThatFindsNothingIsAMissNotARejection) {
  World wall_only;  // the second place alone: no point of map 0 in its frames
  wall_only.points.assign(world_.points.begin() + 1500, world_.points.end());
  wall_only.descriptors = world_.descriptors.rowRange(1500, world_.descriptors.rows).clone();
  for (const int misses : {0, 1}) {
    SCOPED_TRACE(misses);
    config_.merge_verify_frames = 3;
    config_.merge_verify_misses = misses;
    map::Map fresh;
    auto [t, i, x] = in_second_map(fresh);
    std::size_t candidate_at = 0;
    for (; x > 1.0 && candidate_at == 0; ++i, x -= 0.04) {
      ASSERT_EQ(feed(*t, i, x).state, TrackingState::Ok) << i;
      if (t->atlas_stats().merge_candidates == 1) candidate_at = i;
    }
    ASSERT_NE(candidate_at, 0u);
    Frame hidden = testing::synthetic_frame(wall_only, camera_at(x), i, cam_, depth_.bf);
    ASSERT_EQ(t->track(hidden, {}).state, TrackingState::Ok);
    ++i;
    x -= 0.04;
    std::size_t merged_at = 0;
    for (; x > 1.0 && merged_at == 0; ++i, x -= 0.04) {
      ASSERT_EQ(feed(*t, i, x).state, TrackingState::Ok) << i;
      if (t->atlas_stats().merges == 1) merged_at = i;
    }
    ASSERT_NE(merged_at, 0u);
    if (misses == 1) {
      EXPECT_EQ(t->atlas_stats().merges_rejected, 0u);
      EXPECT_EQ(merged_at, candidate_at + 4);  // 3 frames that found it, 1 that missed
    } else {
      EXPECT_EQ(t->atlas_stats().merges_rejected, 1u);  // the hidden frame
      EXPECT_GT(merged_at, candidate_at + 4);
    }
  }
}

// tracking.drop_abandoned_young_maps: map 1, lost 6 frames after its start and left by relocalising in
// map 0, is taken back (its frames leave the trajectory and count as lost); switched off, they stay.
TEST_F(Atlas, AYoungMapLeftForAnOlderMapIsTakenBackWhenSwitchedOn) {
  for (const bool drop : {true, false}) {
    SCOPED_TRACE(drop);
    config_.young_map_frames = 30;
    config_.drop_abandoned_young_maps = drop;
    map::Map fresh;
    auto [t, i, x] = carried_away(fresh, 40 + kLostBeforeNewMap);  // carried away: lost
    const std::size_t map1_start = i;
    for (; i < map1_start + 6; ++i, x -= 0.02) ASSERT_EQ(feed(*t, i, x).state, TrackingState::Ok) << i;
    ASSERT_EQ(t->current_map(), map::MapId{1});
    const std::size_t lost_before = t->lost_frames();
    Frame blank = testing::blank_frame(i++);  // the lens covered: map 1 is lost young
    ASSERT_EQ(t->track(blank, {}).state, TrackingState::Lost);
    // Carried back to the first place: relocalised in map 0 and verified.
    for (x = 0.40; x < 0.50; ++i, x += 0.02) feed(*t, i, x);
    ASSERT_EQ(t->current_map(), map::MapId{0});
    ASSERT_EQ(t->relocalizations(), 1u);
    std::size_t map1_frames_written = 0;
    for (const TrajectoryEntry& e : t->trajectory().entries())
      map1_frames_written += e.frame_index >= map1_start && e.frame_index < map1_start + 6 ? 1 : 0;
    EXPECT_EQ(map1_frames_written, drop ? 0u : 6u);
    EXPECT_EQ(t->atlas_stats().young_maps_dropped, drop ? 1u : 0u);
    EXPECT_EQ(t->atlas_stats().frames_withdrawn, drop ? 6u : 0u);
    EXPECT_EQ(t->lost_frames(), lost_before + 1 + (drop ? 6u : 0u));  // the blank frame, and map 1's
  }
}

// tracking.merge_verify_frames: a candidate found at frame c is merged at frame c + merge_verify_frames,
// each frame between having found the other map where the candidate transform puts it.
TEST_F(Atlas, AMergeWaitsForItsVerificationFrames) {
  for (const int verify : {3, 6}) {
    SCOPED_TRACE(verify);
    config_.merge_verify_frames = verify;
    map::Map fresh;
    auto [t, i, x] = in_second_map(fresh);
    std::size_t candidate_at = 0, merged_at = 0;
    for (; x > 1.0 && merged_at == 0; ++i, x -= 0.04) {
      ASSERT_EQ(feed(*t, i, x).state, TrackingState::Ok) << i;
      if (candidate_at == 0 && t->atlas_stats().merge_candidates == 1) candidate_at = i;
      if (t->atlas_stats().merges == 1) merged_at = i;
    }
    ASSERT_NE(merged_at, 0u);
    EXPECT_EQ(t->atlas_stats().merges_rejected, 0u);
    EXPECT_EQ(merged_at, candidate_at + static_cast<std::size_t>(verify));
  }
}

// tracking.merge_min_inliers: the inliers a merge search's pose in the other map needs, apart from
// relocalisation's min_inliers_after_reloc. Walking back into the first place, each frame sees a few
// hundred of its points: a bar above that never merges, while relocalisation's bar is untouched.
TEST_F(Atlas, AMergeNeedsMergeMinInliersInTheOtherMap) {
  for (const int needed : {50, 2000}) {
    SCOPED_TRACE(needed);
    config_.merge_min_inliers = needed;
    map::Map fresh;
    auto [t, i, x] = in_second_map(fresh);
    for (; x > 1.0; ++i, x -= 0.04) ASSERT_EQ(feed(*t, i, x).state, TrackingState::Ok) << i;
    EXPECT_EQ(t->atlas_stats().merges, needed == 50 ? 1u : 0u);
    EXPECT_EQ(t->open_maps().size(), needed == 50 ? 1u : 2u);
  }
}

// tracking.new_map_seed_motion_frames: a camera that keeps walking while it cannot be tracked (here the
// wall it walks along shows a texture the map has never seen, so relocalisation finds nothing) starts
// its new map where the last trusted frames' motion carried it; held at the last trusted pose, the new
// map and every frame tracked in it are off by the distance walked while lost (it never merges here).
TEST_F(Atlas, ANewMapIsSeededWhereTheTrustedMotionCarriedTheCamera) {
  World unseen_texture = world_;
  std::mt19937 rng(77);
  unseen_texture.descriptors = testing::random_descriptors(static_cast<int>(world_.points.size()), rng);
  for (const int window : {0, 10}) {
    SCOPED_TRACE(window);
    config_.new_map_seed_motion_frames = window;
    map::Map fresh;
    auto t = make_tracker(fresh);
    std::size_t i = walk_first_place(*t);  // x = 0.02 i: the last trusted frame 39 at x = 0.78
    map::KeyframeId seed = map::kNoKeyframe;
    std::size_t seeded_at = 0;
    for (; i < 80; ++i) {
      const double x = 0.02 * static_cast<double>(i);
      truth_[i] = x;
      Frame f = testing::synthetic_frame(unseen_texture, camera_at(x), i, cam_, depth_.bf);
      const TrackOutcome o = t->track(f, {});
      if (seed == map::kNoKeyframe && t->atlas_stats().maps_created == 2) {
        seed = o.new_keyframe;
        seeded_at = i;
      }
    }
    ASSERT_NE(seed, map::kNoKeyframe);
    EXPECT_EQ(t->atlas_stats().merges, 0u);
    map::MapView view = fresh.view();
    const double seed_x = view.keyframe(seed)->camera_center().x();
    const double walked_lost = truth_[seeded_at] - 0.78;
    ASSERT_GT(walked_lost, 0.15);
    if (window == 0) {
      EXPECT_NEAR(seed_x, 0.78, 1e-3);
    } else {
      EXPECT_NEAR(seed_x, truth_[seeded_at], 1e-3);
    }
    // Every frame tracked in the new map is as far off as its seed.
    std::size_t in_new_map = 0;
    for (const auto& p : t->trajectory().resolve(view)) {
      const auto index = static_cast<std::size_t>(std::lround(p.stamp * 30.0));
      if (index < seeded_at) continue;
      ++in_new_map;
      EXPECT_NEAR(p.T_wc.translation().x(), truth_.at(index) - (window == 0 ? walked_lost : 0.0), 0.005)
          << index;
    }
    EXPECT_GE(in_new_map, 15u);
  }
}

TEST(AtlasConfig, KeyIsReadAndRangeChecked) {
  EXPECT_EQ(TrackerConfig{}.new_map_after_lost_frames, 15);
  EXPECT_TRUE(TrackerConfig{}.drop_abandoned_young_maps);
  const TrackerConfig c =
      TrackerConfig::from_yaml(ConfigReader::from_string("new_map_after_lost_frames: 0\n", "tracking.yaml"));
  EXPECT_EQ(c.new_map_after_lost_frames, 0);
  EXPECT_EQ(TrackerConfig{}.young_map_frames, 30);
  EXPECT_EQ(TrackerConfig{}.merge_verify_frames, 3);
  EXPECT_EQ(TrackerConfig{}.merge_verify_misses, 3);
  EXPECT_EQ(TrackerConfig{}.merge_min_inliers, TrackerConfig{}.min_inliers_after_reloc);
  EXPECT_THROW(TrackerConfig::from_yaml(ConfigReader::from_string("merge_min_inliers: 4\n", "t.yaml")),
               Error);
  EXPECT_EQ(TrackerConfig{}.new_map_seed_motion_frames, 0);  // off: measured, not adopted (session 44)
  EXPECT_EQ(TrackerConfig{}.new_map_seed_max_frames, 30);
  EXPECT_EQ(TrackerConfig::from_yaml(ConfigReader::from_string("new_map_seed_motion_frames: 10\n", "t.yaml"))
                .new_map_seed_motion_frames,
            10);
  EXPECT_THROW(
      TrackerConfig::from_yaml(ConfigReader::from_string("new_map_seed_motion_frames: 301\n", "t.yaml")),
      Error);
  EXPECT_EQ(TrackerConfig::from_yaml(ConfigReader::from_string("merge_verify_frames: 6\n", "t.yaml"))
                .merge_verify_frames,
            6);
  EXPECT_THROW(TrackerConfig::from_yaml(ConfigReader::from_string("merge_verify_frames: -1\n", "t.yaml")),
               ConfigError);
  EXPECT_EQ(
      TrackerConfig::from_yaml(ConfigReader::from_string("young_map_frames: 0\n", "t.yaml")).young_map_frames,
      0);
  EXPECT_THROW(TrackerConfig::from_yaml(ConfigReader::from_string("young_map_frames: -1\n", "t.yaml")),
               ConfigError);
  EXPECT_TRUE(
      TrackerConfig::from_yaml(ConfigReader::from_string("drop_abandoned_young_maps: true\n", "t.yaml"))
          .drop_abandoned_young_maps);
  EXPECT_EQ(TrackerConfig::from_yaml(ConfigReader::from_string("merge_verify_misses: 2\n", "t.yaml"))
                .merge_verify_misses,
            2);
  EXPECT_THROW(TrackerConfig::from_yaml(ConfigReader::from_string("merge_verify_misses: -1\n", "t.yaml")),
               ConfigError);
  EXPECT_THROW(
      TrackerConfig::from_yaml(ConfigReader::from_string("new_map_after_lost_frames: -1\n", "t.yaml")),
      ConfigError);
}

}  // namespace
}  // namespace sp::track
