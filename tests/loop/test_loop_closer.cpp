// The loop closer on a generated loop: a camera walks a 0.5 m circle inside a cylindrical room looking
// outwards, 48 keyframes 7.5 degrees apart. The map holds them at drifted poses (the drift grows along the
// path to 8 cm and 3 degrees at the end) and their points back-projected from those poses; the last
// keyframes see the first keyframes' place as new points (an unclosed loop). Verification must find the
// true pose of the query, correction must bring every keyframe and every point back near the truth, and
// the loop's keyframes must be held against culling between verification and correction.
#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <future>

#include "../support/synthetic_map.hpp"
#include "stillpoint/loop/loop_closer.hpp"
#include "stillpoint/loop/loop_verifier.hpp"
#include "stillpoint/loop/pose_graph_correction.hpp"
#include "stillpoint/tracking/pose_guard.hpp"

namespace sp::loop {
namespace {

constexpr int kKeyframes = 48;

geo::SE3 true_pose(int k) {
  const double a = 2.0 * M_PI * k / kKeyframes;
  return testing::camera_pose(0.5 * Eigen::Vector3d(std::sin(a), 0.0, std::cos(a)), a);
}

// World-frame drift after the share s of the path: estimated T_wc = drift(s) * true T_wc.
geo::SE3 drift(double s) {
  return geo::SE3(Eigen::Quaterniond(Eigen::AngleAxisd(s * 3.0 * M_PI / 180.0, Eigen::Vector3d::UnitY())),
                  s * Eigen::Vector3d(0.06, 0.02, -0.05));
}

geo::SE3 drifted_pose(int k) {
  return true_pose(k) * drift(static_cast<double>(k) / (kKeyframes - 1)).inverse();
}

class LoopCloserTest : public ::testing::Test {
 protected:
  void SetUp() override {
    scene_ = testing::make_cylinder_scene(2000, 3.0, 1.0, 7);
    testing::SyntheticMapBuilder builder(map_, scene_, cam_, depth_.bf, 12);
    for (int k = 0; k < kKeyframes; ++k) ids_.push_back(builder.add(true_pose(k), drifted_pose(k)));
    builder.finish(pyramid_);
    drift_at_end_ = max_keyframe_error();
    map::MapView view = map_.view();
    for (const auto& [pid, p] : view.points()) {
      if (const auto row = builder.row_of(pid)) row_of_[pid] = *row;
    }
  }

  std::unique_ptr<LoopCloser> make_closer(const std::string& detector = "off",
                                          std::shared_ptr<const Vocabulary> vocabulary = nullptr) {
    LoopClosingConfig c;
    c.detector = detector;
    c.global_ba = false;  // the correction alone is under test
    return std::make_unique<LoopCloser>(map_, c, std::move(vocabulary), cam_, depth_, pyramid_, true);
  }

  // Largest keyframe position error against the truth (the first keyframe fixes the gauge).
  double max_keyframe_error() {
    map::MapView view = map_.view();
    double worst = 0;
    for (int k = 0; k < kKeyframes; ++k) {
      const map::Keyframe* kf = view.keyframe(ids_[static_cast<std::size_t>(k)]);
      worst = std::max(worst, track::pose_deviation(kf->T_cw, true_pose(k)).translation_m);
    }
    return worst;
  }

  double point_error(map::MapView& view, map::PointId pid) {
    return (view.point(pid)->position - scene_.points[static_cast<std::size_t>(row_of_.at(pid))]).norm();
  }

  map::Map map_;
  geo::CameraIntrinsics cam_;
  track::DepthModel depth_;
  map::ScalePyramid pyramid_ = map::ScalePyramid::make(8, 1.2);
  testing::SyntheticScene scene_;
  std::vector<map::KeyframeId> ids_;
  std::unordered_map<map::PointId, int> row_of_;
  double drift_at_end_ = 0;  // largest keyframe position error before any correction
};

TEST_F(LoopCloserTest, VerifiesTheTruePoseAndCorrectsTheDrift) {
  const double before = max_keyframe_error();
  ASSERT_GT(before, 0.07);  // the drift at the end of the path: |(0.06, 0.02, -0.05)| plus the turn
  auto closer = make_closer();
  auto loop = closer->verify(ids_.back(), ids_[1]);
  ASSERT_TRUE(loop.has_value());
  // Exact projections: the verified pose is the true one up to the solver's tolerance.
  const track::PoseDeviation d = track::pose_deviation(loop->T_query_w, true_pose(kKeyframes - 1));
  EXPECT_LT(d.translation_m, 0.002);
  EXPECT_LT(d.rotation_deg, 0.1);
  ASSERT_TRUE(closer->correct(std::move(*loop)));
  // The drift grew evenly along the path, which is what a pose graph spreads a loop error as; a
  // quarter of it left anywhere would mean the correction did not reach that part of the loop.
  const double after = max_keyframe_error();
  EXPECT_LT(after, 0.25 * before) << "before " << before << " m";
  map::MapView view = map_.view();
  EXPECT_TRUE(view.keyframe(ids_.back())->loop_edges.contains(ids_[1]));
}

TEST_F(LoopCloserTest, EveryPointIsCorrectedOnceAndEndsNearTheTruth) {
  // The points the query's group sees but another keyframe made: moved with the group, they must not
  // move again with their reference keyframe in the pose graph step.
  std::vector<map::PointId> shared;
  {
    map::MapView view = map_.view();
    std::vector<map::KeyframeId> group = view.best_covisibles(ids_.back(), 1000);
    group.push_back(ids_.back());
    for (const auto& [pid, p] : view.points()) {
      if (p.bad || std::find(group.begin(), group.end(), p.reference) != group.end()) continue;
      for (const auto& [k, f] : p.observations)
        if (std::find(group.begin(), group.end(), k) != group.end()) {
          shared.push_back(pid);
          break;
        }
    }
  }
  ASSERT_GT(shared.size(), 20u);  // the case is there to be tested
  auto closer = make_closer();
  auto loop = closer->verify(ids_.back(), ids_[1]);
  ASSERT_TRUE(loop.has_value());
  ASSERT_TRUE(closer->correct(std::move(*loop)));

  map::MapView view = map_.view();
  // These points lie where the group keyframes put them, and the group ends within millimetres of
  // the truth (the test above): 3 cm leaves room for the residual rotation at 3 m. Moved a second
  // time with their reference keyframe's share of the loop, they were 17-22 cm off.
  double worst_shared = 0;
  for (map::PointId pid : shared) {
    const map::MapPoint* p = view.live_point(pid);
    ASSERT_NE(p, nullptr);
    worst_shared = std::max(worst_shared, point_error(view, p->id));
  }
  EXPECT_LT(worst_shared, 0.03);
  // Every other point follows its keyframe, which keeps part of the spread drift mid-path: all must
  // end within half of the drift the loop removed (a point moved twice is off by more than all of it).
  std::size_t live = 0, far = 0;
  for (const auto& [pid, p] : view.points()) {
    if (p.bad) continue;
    ++live;
    if (point_error(view, pid) > 0.5 * drift_at_end_) ++far;
  }
  EXPECT_GT(live, 1000u);
  EXPECT_EQ(far, 0u);
}

TEST_F(LoopCloserTest, LoopKeyframesAreHeldAgainstCullingUntilCorrected) {
  auto closer = make_closer();
  auto loop = closer->verify(ids_.back(), ids_[1]);
  ASSERT_TRUE(loop.has_value());
  {
    // Between verification and correction local mapping may cull: it must be refused for both.
    map::MapView view = map_.view();
    EXPECT_FALSE(view.erase_keyframe(ids_.back()));
    EXPECT_FALSE(view.erase_keyframe(ids_[1]));
    EXPECT_FALSE(view.keyframe(ids_.back())->bad);
    EXPECT_FALSE(view.keyframe(ids_[1])->bad);
  }
  ASSERT_TRUE(closer->correct(std::move(*loop)));
  map::MapView view = map_.view();
  EXPECT_EQ(view.keyframe(ids_.back())->culling_holds, 0);
  EXPECT_EQ(view.keyframe(ids_[1])->culling_holds, 0);
  EXPECT_TRUE(view.erase_keyframe(ids_[1]));  // released: culling may take it now
}

TEST_F(LoopCloserTest, AnUncorrectedLoopReleasesItsKeyframes) {
  auto closer = make_closer();
  {
    auto loop = closer->verify(ids_.back(), ids_[1]);
    ASSERT_TRUE(loop.has_value());
  }
  map::MapView view = map_.view();
  EXPECT_EQ(view.keyframe(ids_.back())->culling_holds, 0);
  EXPECT_TRUE(view.erase_keyframe(ids_.back()));
}

TEST_F(LoopCloserTest, AWrongPlaceIsNotVerified) {
  // Keyframe 24 looks the other way (180 degrees): no common points with the query.
  auto closer = make_closer();
  EXPECT_FALSE(closer->verify(ids_.back(), ids_[24]).has_value());
}

// Verification reads a copy taken under one short view, so it runs while another stage holds the
// map lock, and the map changing afterwards does not change its answer.
TEST_F(LoopCloserTest, VerificationRunsOnItsCopyWhileTheMapIsLocked) {
  LoopClosingConfig c;
  const LoopVerifier verifier(c.verification, cam_, depth_, pyramid_);
  std::optional<LoopEvidence> evidence;
  {
    const map::MapReader view = map_.reader();
    evidence = gather_evidence(view, ids_.back(), ids_[1]);
    ASSERT_TRUE(evidence.has_value());
    ASSERT_TRUE(add_loop_side(view, *evidence, c.verification.verify_neighbours));
  }
  finish_evidence(*evidence);
  EXPECT_FALSE(evidence->neighbours.empty());  // the neighbour check has views to run on
  std::future<LoopVerification> running;  // declared first: on failure the view is released before the wait
  {
    map::MapView view = map_.view();  // held by "another stage" for the whole verification
    // The map moves on meanwhile: every point 1 m off. The copy keeps the positions it was given.
    for (const auto& [pid, p] : view.points()) view.point(pid)->position += Eigen::Vector3d(1.0, 0.0, 0.0);
    running = std::async(std::launch::async, [&] { return verifier.verify(*evidence); });
    ASSERT_EQ(running.wait_for(std::chrono::seconds(60)), std::future_status::ready)
        << "verification waited for the map lock";
  }
  const LoopVerification result = running.get();
  ASSERT_TRUE(result.accepted());
  const track::PoseDeviation d = track::pose_deviation(result.T_query_w, true_pose(kKeyframes - 1));
  EXPECT_LT(d.translation_m, 0.002);
  EXPECT_LT(d.rotation_deg, 0.1);
}

// A keyframe culled between the two copies ends the verification: no loop side is copied for it, and
// nothing is gathered for a culled keyframe.
TEST_F(LoopCloserTest, AKeyframeCulledBetweenTheCopiesEndsTheVerification) {
  std::optional<LoopEvidence> evidence;
  {
    const map::MapReader view = map_.reader();
    evidence = gather_evidence(view, ids_.back(), ids_[1]);
  }
  ASSERT_TRUE(evidence.has_value());
  {
    map::MapView view = map_.view();  // local mapping culls the match meanwhile
    ASSERT_TRUE(view.erase_keyframe(ids_[1]));
  }
  const map::MapReader view = map_.reader();
  EXPECT_FALSE(add_loop_side(view, *evidence, 4));
  EXPECT_FALSE(gather_evidence(view, ids_.back(), ids_[1]).has_value());
}

// The pose graph is solved on a copy while tracking and local mapping go on; the solution must then land
// on the map as it has become: a keyframe local BA moved keeps that motion on top of its correction, a
// keyframe made meanwhile follows its parent, points follow the keyframe that corrected them.
TEST_F(LoopCloserTest, ThePoseGraphSolvedOffTheLockLandsOnTheMapAsItBecame) {
  std::unordered_map<map::KeyframeId, geo::SE3> old_pose;
  EssentialGraph graph;
  {
    const map::MapReader view = map_.reader();
    for (map::KeyframeId k : view.keyframe_ids_sorted()) old_pose[k] = view.keyframe(k)->T_cw;
    graph = essential_graph(view, ids_.back(), ids_[1], old_pose, {});
  }
  ASSERT_EQ(graph.vertices.size(), ids_.size());
  EXPECT_GE(graph.edges.size(), ids_.size() - 1);  // at least the spanning tree
  // A "solution": every free keyframe moved by its own small twist.
  std::mt19937 rng(3);
  std::normal_distribution<double> n(0.0, 0.01);
  for (auto& v : graph.vertices) {
    if (v.fixed) continue;
    geo::Vec6 xi;
    for (int i = 0; i < 6; ++i) xi[i] = n(rng);
    v.T_cw = geo::SE3::exp(xi) * v.T_cw;
  }
  auto solved = [&](map::KeyframeId k) {
    for (const auto& v : graph.vertices)
      if (v.id == k.value()) return v.T_cw;
    throw std::logic_error("no vertex");
  };
  const map::KeyframeId moved = ids_[20], parent = ids_[30], untouched = ids_[10];
  geo::Vec6 local_ba;
  local_ba << 0.002, -0.001, 0.003, 0.001, 0.0, -0.002;
  const geo::SE3 moved_to = geo::SE3::exp(local_ba) * old_pose.at(moved);
  map::KeyframeId added = map::kNoKeyframe;
  map::PointId reference_point = map::kNoPoint, overridden_point = map::kNoPoint;
  Eigen::Vector3d reference_point_was, overridden_point_was;
  std::unordered_map<map::PointId, map::KeyframeId> corrected_by;
  {
    map::MapView view = map_.view();  // meanwhile: local BA moves a keyframe, tracking adds one
    view.keyframe(moved)->T_cw = moved_to;
    map::Keyframe kf;
    kf.T_cw = geo::SE3::exp(local_ba) * old_pose.at(parent);
    added = view.add_keyframe(std::move(kf));
    view.keyframe(added)->parent = parent;
    for (const auto& [pid, p] : view.points()) {
      if (p.bad) continue;
      if (reference_point == map::kNoPoint && p.reference == ids_[5]) {
        reference_point = pid;
        reference_point_was = p.position;
      } else if (overridden_point == map::kNoPoint && p.reference == ids_[6]) {
        overridden_point = pid;
        overridden_point_was = p.position;
      }
    }
  }
  ASSERT_NE(reference_point, map::kNoPoint);
  ASSERT_NE(overridden_point, map::kNoPoint);
  corrected_by[overridden_point] = ids_[40];
  geo::SE3 added_was;
  {
    map::MapView view = map_.view();
    added_was = view.keyframe(added)->T_cw;
    apply_pose_graph(view, graph, corrected_by, pyramid_);
  }
  const map::MapReader view = map_.reader();
  EXPECT_EQ(view.keyframe(untouched)->T_cw.matrix(), solved(untouched).matrix());
  const geo::SE3 moved_expected = moved_to * old_pose.at(moved).inverse() * solved(moved);
  EXPECT_LT((view.keyframe(moved)->T_cw.matrix() - moved_expected.matrix()).norm(), 1e-12);
  EXPECT_GT((view.keyframe(moved)->T_cw.matrix() - solved(moved).matrix()).norm(), 1e-3);
  const geo::SE3 added_expected = added_was * old_pose.at(parent).inverse() * solved(parent);
  EXPECT_LT((view.keyframe(added)->T_cw.matrix() - added_expected.matrix()).norm(), 1e-12);
  auto moved_with = [&](map::KeyframeId k, const Eigen::Vector3d& p) {
    return Eigen::Vector3d(solved(k).inverse() * (old_pose.at(k) * p));
  };
  EXPECT_LT((view.point(reference_point)->position - moved_with(ids_[5], reference_point_was)).norm(), 1e-12);
  EXPECT_LT((view.point(overridden_point)->position - moved_with(ids_[40], overridden_point_was)).norm(),
            1e-12);
  EXPECT_GT((view.point(overridden_point)->position - moved_with(ids_[6], overridden_point_was)).norm(),
            1e-4);
}

TEST_F(LoopCloserTest, DetectsTheLoopFromTheKeyframeStreamAndClosesIt) {
  const auto vocabulary_file = std::filesystem::path(SP_SOURCE_DIR) / "data" / "vocab" / "stillpoint_orb.spv";
  auto vocabulary = std::make_shared<const Vocabulary>(Vocabulary::load(vocabulary_file));
  const double before = max_keyframe_error();
  auto closer = make_closer("bow-keyframe", vocabulary);
  for (map::KeyframeId k : ids_) closer->process(k);
  const LoopClosingStats s = closer->stats();
  ASSERT_EQ(s.loops_closed, 1u);
  ASSERT_EQ(s.closures.size(), 1u);
  // The loop joins the end of the path to its start (both stamps within the first / last 4 keyframes).
  EXPECT_GT(s.closures[0].query_stamp, (kKeyframes - 5) / 30.0);
  EXPECT_LT(s.closures[0].match_stamp, 4 / 30.0);
  EXPECT_LT(max_keyframe_error(), 0.25 * before);
}

// A loaded map's keyframes are filed through add_existing_keyframes without a descriptor; with a learned
// detector the closer describes their thumbnails, so the hybrid re-ranks candidates against them and the
// loop back into the loaded part still closes.
TEST_F(LoopCloserTest, KeyframesOfALoadedMapAreDescribedForTheHybridDetector) {
  const auto vocabulary_file = std::filesystem::path(SP_SOURCE_DIR) / "data" / "vocab" / "stillpoint_orb.spv";
  auto vocabulary = std::make_shared<const Vocabulary>(Vocabulary::load(vocabulary_file));
  {
    map::MapView view = map_.view();
    for (map::KeyframeId id : ids_)
      view.keyframe(id)->thumbnail = cv::Mat(24, 32, CV_8UC3, cv::Scalar::all(90));
  }
  LoopClosingConfig c;
  c.detector = "hybrid";
  c.detection.hybrid.bow = "bow-keyframe";
  c.global_ba = false;
  LoopCloser closer(map_, c, vocabulary, cam_, depth_, pyramid_, true);
  ASSERT_TRUE(closer.needs_global_descriptors());
  std::size_t described = 0;
  closer.set_global_describer([&](const cv::Mat& bgr) {
    EXPECT_FALSE(bgr.empty());
    ++described;
    return Eigen::VectorXf(Eigen::VectorXf::Ones(8).normalized());  // every place alike: nothing vetoed
  });
  // The first half is "loaded": BoW only, as SlamSystem files a loaded map.
  const std::size_t loaded = ids_.size() / 2;
  std::vector<KeyframeInfo> existing;
  for (std::size_t i = 0; i < loaded; ++i) {
    KeyframeInfo k;
    k.id = ids_[i];
    map::MapView view = map_.view();
    k.R_cw = view.keyframe(k.id)->T_cw.rotation();
    k.bow = vocabulary->transform(view.keyframe(k.id)->features.descriptors);
    existing.push_back(std::move(k));
  }
  closer.add_existing_keyframes(existing);
  EXPECT_EQ(described, loaded);
  for (std::size_t i = loaded; i < ids_.size(); ++i) closer.process(ids_[i]);
  EXPECT_EQ(described, ids_.size());
  const LoopClosingStats s = closer.stats();
  EXPECT_EQ(s.undescribed_candidates, 0u);
  EXPECT_GT(s.candidates, 0u);
  EXPECT_EQ(s.loops_closed, 1u);
}

}  // namespace
}  // namespace sp::loop
