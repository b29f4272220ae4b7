// The tracker's global relocalisation on a small generated map: points with unique random descriptors,
// frames made of their exact projections (depth and virtual stereo included), no images. The tracker
// builds its own map along a path, loses it on a frame without features, and must find a pose far
// from where it was lost (candidates from the provider, i.e. the BoW database in a run), then verify
// it over the next frames before it writes any of them; a relocalised pose that the next frames do
// not follow is rejected.
#include <gtest/gtest.h>

#include <random>

#include "../support/synthetic_frame.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/tracking/tracker.hpp"

namespace sp::track {
namespace {

using Scene = testing::SyntheticScene;

Scene make_scene(int n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> x(-2.5, 2.5), y(-1.8, 1.8), z(2.0, 4.0);
  std::uniform_int_distribution<int> byte(0, 255);
  Scene s;
  s.descriptors = cv::Mat(n, 32, CV_8U);
  for (int i = 0; i < n; ++i) {
    s.points.emplace_back(x(rng), y(rng), z(rng));
    for (int b = 0; b < 32; ++b) s.descriptors.at<std::uint8_t>(i, b) = static_cast<std::uint8_t>(byte(rng));
  }
  return s;
}

// The camera looks down +z from (x, 0, 0): T_cw is a pure translation by -x.
geo::SE3 camera_at(double x) { return geo::SE3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(-x, 0, 0)); }

class Relocalization : public ::testing::Test {
 protected:
  void SetUp() override {
    config_.keyframes.policy = "heuristic";
    scene_ = make_scene(1500, 3);
  }
  std::unique_ptr<Tracker> make_tracker() {
    return std::make_unique<Tracker>(map_, config_, cam_, depth_, map::ScalePyramid::make(8, 1.2), 30.0);
  }
  // Tracks frames 0..n-1 along x from 0 to `to` metres; all must be tracked.
  void build_map(Tracker& t, std::size_t n, double to) {
    for (std::size_t i = 0; i < n; ++i) {
      Frame f = testing::synthetic_frame(
          scene_, camera_at(to * static_cast<double>(i) / static_cast<double>(n - 1)), i, cam_, depth_.bf);
      ASSERT_EQ(t.track(f, {}).state, TrackingState::Ok) << "frame " << i;
    }
  }
  TrackOutcome feed(Tracker& t, std::size_t index, double x) {
    Frame f = testing::synthetic_frame(scene_, camera_at(x), index, cam_, depth_.bf);
    return t.track(f, {});
  }
  [[nodiscard]] double x_of(const Tracker& t, std::size_t frame_index) {
    map::MapView view = map_.view();
    for (const auto& p : t.trajectory().resolve(view))
      if (std::abs(p.stamp - static_cast<double>(frame_index) / 30.0) < 1e-9) return p.T_wc.translation().x();
    return std::nan("");
  }

  map::Map map_;
  TrackerConfig config_;
  geo::CameraIntrinsics cam_;
  DepthModel depth_;
  Scene scene_;
};

TEST_F(Relocalization, FindsAPoseFarFromWhereItWasLostAndVerifiesIt) {
  config_.relocalization_verify_frames = 3;
  auto t = make_tracker();
  build_map(*t, 40, 0.8);  // 2 cm a frame
  Frame lost = testing::blank_frame(40);
  EXPECT_EQ(t->track(lost, {}).state, TrackingState::Lost);
  // Kidnapped back to 0.1 m (0.7 m from where it was lost), then moving on at 1 cm a frame.
  const TrackOutcome first = feed(*t, 41, 0.10);
  EXPECT_TRUE(first.relocalized);
  EXPECT_TRUE(first.verifying);
  EXPECT_EQ(first.state, TrackingState::Lost);  // not trusted yet
  EXPECT_EQ(first.new_keyframe, map::kNoKeyframe);
  for (std::size_t i = 42; i < 44; ++i) {
    const TrackOutcome o = feed(*t, i, 0.10 + 0.01 * static_cast<double>(i - 41));
    EXPECT_TRUE(o.verifying) << i;
    EXPECT_EQ(o.new_keyframe, map::kNoKeyframe) << i;
  }
  EXPECT_TRUE(std::isnan(x_of(*t, 41)));             // nothing written while verifying
  const TrackOutcome verified = feed(*t, 44, 0.13);  // the third frame after it: verified
  EXPECT_EQ(verified.state, TrackingState::Ok);
  EXPECT_FALSE(verified.verifying);
  EXPECT_EQ(t->relocalizations(), 1u);
  EXPECT_EQ(t->relocalization_stats().accepted, 1u);
  EXPECT_EQ(t->relocalization_stats().ambiguous, 0u);  // every candidate that located it agreed
  EXPECT_EQ(t->relocalization_stats().rejected_by_consistency, 0u);
  EXPECT_EQ(t->first_relocalization_frame(), std::optional<std::size_t>(41));
  // The verified frames are written after all, at their true places; only the blank frame is lost.
  for (std::size_t i = 41; i <= 44; ++i)
    EXPECT_NEAR(x_of(*t, i), 0.10 + 0.01 * static_cast<double>(i - 41), 1e-3);
  EXPECT_EQ(t->lost_frames(), 1u);
  EXPECT_EQ(t->trajectory().size(), 44u);
}

TEST_F(Relocalization, RejectsAPoseTheNextFramesDoNotFollow) {
  config_.relocalization_verify_frames = 3;
  auto t = make_tracker();
  build_map(*t, 40, 0.8);
  Frame lost = testing::blank_frame(40);
  t->track(lost, {});
  EXPECT_TRUE(feed(*t, 41, 0.10).relocalized);
  // The next frame is 30 cm away (the relocalised pose was not where the camera is): rejected.
  const TrackOutcome jump = feed(*t, 42, 0.40);
  EXPECT_EQ(jump.state, TrackingState::Lost);
  EXPECT_FALSE(jump.verifying);
  EXPECT_EQ(t->relocalization_stats().rejected_by_consistency, 1u);
  EXPECT_EQ(t->relocalizations(), 0u);
  EXPECT_TRUE(std::isnan(x_of(*t, 41)));
  EXPECT_EQ(t->lost_frames(), 3u);  // the blank frame, the rejected pose and the frame that broke it
  // Still lost, so the next frame relocalises again and, followed this time, is accepted.
  EXPECT_TRUE(feed(*t, 43, 0.41).relocalized);
  for (std::size_t i = 44; i <= 46; ++i) feed(*t, i, 0.41 + 0.01 * static_cast<double>(i - 43));
  EXPECT_EQ(t->relocalizations(), 1u);
  EXPECT_EQ(t->relocalization_stats().poses_found, 2u);
  EXPECT_NEAR(x_of(*t, 43), 0.41, 1e-3);
}

TEST_F(Relocalization, WithoutVerificationThePoseIsTrustedAtOnce) {
  config_.relocalization_verify_frames = 0;
  auto t = make_tracker();
  build_map(*t, 40, 0.8);
  Frame lost = testing::blank_frame(40);
  t->track(lost, {});
  const TrackOutcome o = feed(*t, 41, 0.10);
  EXPECT_TRUE(o.relocalized);
  EXPECT_EQ(o.state, TrackingState::Ok);
  EXPECT_EQ(t->relocalizations(), 1u);
  EXPECT_NEAR(x_of(*t, 41), 0.10, 1e-3);
}

TEST_F(Relocalization, ProviderCandidatesAreTriedFirst) {
  // Only the newest keyframe as a recent candidate (and its covisibles): the provider must supply one
  // near the kidnap target, as the BoW database does in a run.
  config_.relocalization_candidates = 1;
  config_.relocalization_verify_frames = 0;
  config_.reloc_agreeing_candidates = 0;  // no other candidate asked to agree
  auto t = make_tracker();
  std::vector<map::KeyframeId> asked;
  t->set_relocalization_candidates([&asked](const map::MapReader& view, const Frame&) {
    std::vector<map::KeyframeId> ids = view.keyframe_ids_sorted();
    asked.push_back(ids.front());
    return std::vector<map::KeyframeId>{ids.front()};
  });
  build_map(*t, 40, 0.8);
  Frame lost = testing::blank_frame(40);
  t->track(lost, {});
  EXPECT_TRUE(asked.empty());  // the blank frame lost tracking; relocalisation starts on the next
  EXPECT_TRUE(feed(*t, 41, 0.02).relocalized);
  EXPECT_EQ(asked.size(), 1u);
  EXPECT_EQ(t->relocalization_stats().attempts, 1u);
  EXPECT_EQ(t->relocalization_stats().candidates_tried, 1u);  // the provider's keyframe, first and enough
}

TEST(RelocalizationConfig, KeysAreReadAndRangeChecked) {
  const TrackerConfig c = TrackerConfig::from_yaml(ConfigReader::from_string(
      "relocalization_verify_frames: 5\nrelocalization_max_step_m: 0.1\nrelocalization_max_step_deg: 8\n",
      "tracking.yaml"));
  EXPECT_EQ(c.relocalization_verify_frames, 5);
  EXPECT_TRUE(c.reloc_pnp_inliers_only);  // the default
  EXPECT_EQ(c.reloc_agreeing_candidates, 2);
  EXPECT_DOUBLE_EQ(c.relocalization_max_step_m, 0.1);
  EXPECT_DOUBLE_EQ(c.relocalization_max_step_deg, 8.0);
  EXPECT_THROW(TrackerConfig::from_yaml(ConfigReader::from_string("relocalization_verify_frames: -1\n", "t")),
               ConfigError);
  const TrackerConfig d = TrackerConfig::from_yaml(ConfigReader::from_string(
      "reloc_pnp_inliers_only: false\nreloc_agreeing_candidates: 0\nmerge_agreeing_candidates: 4\n", "t"));
  EXPECT_FALSE(d.reloc_pnp_inliers_only);
  EXPECT_EQ(d.reloc_agreeing_candidates, 0);
  EXPECT_EQ(d.merge_agreeing_candidates, 4);
  EXPECT_THROW(TrackerConfig::from_yaml(ConfigReader::from_string("reloc_agreeing_candidates: -1\n", "t")),
               ConfigError);
  EXPECT_THROW(TrackerConfig::from_yaml(ConfigReader::from_string("relocalization_max_step_m: 0\n", "t")),
               ConfigError);
}

}  // namespace
}  // namespace sp::track
