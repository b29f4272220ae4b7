// End-to-end map reuse: map the first 100 frames of a dynsynth cut and save the map, then run the
// last 50 frames with that map loaded. The second run must relocalise within a few frames, keep the
// loaded keyframes as they were, and report poses in the FIRST run's frame (a re-initialisation at
// the identity would be off by the ~0.34 m the camera has moved by frame 100).
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>

#include "../support/shared_data.hpp"
#include "stillpoint/api/runner.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/io/trajectory_io.hpp"
#include "stillpoint/io/tum_sequence.hpp"
#include "stillpoint/map/map_file.hpp"
#include "stillpoint/pipeline/slam_system.hpp"

namespace sp::pipeline {
namespace {

using api::run_slam;  // stillpoint run's runner, on the public API
using api::RunOptions;
using api::RunResult;

const std::filesystem::path kSequence =
    std::filesystem::path(SP_SHARED_DIR) / "data" / "dynsynth" / "office_a_walking_xyz_150";
const std::filesystem::path kConfig = std::filesystem::path(SP_SOURCE_DIR) / "config" / "stillpoint.yaml";
constexpr std::size_t kSplit = 100;

std::filesystem::path scratch(const std::string& name) {
  const auto dir = std::filesystem::path(SP_TEST_TMP_DIR) / "e2e_map" / name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

RunResult run_part(std::size_t start, std::size_t frames, const std::filesystem::path& out,
                   const std::optional<std::filesystem::path>& load,
                   const std::optional<std::filesystem::path>& save,
                   const std::function<void(SystemConfig&)>& tweak = {}) {
  io::TumSequenceOptions seq;
  seq.start_frame = start;
  seq.max_frames = frames;
  io::TumSequence source(kSequence, seq);
  SystemConfig config = SystemConfig::load(kConfig);
  config.dynamic.mode = "oracle";
  if (tweak) tweak(config);
  RunOptions options;
  options.out_dir = out;
  options.deterministic = true;
  options.progress = false;
  options.groundtruth = source.groundtruth_path();
  options.boxes_file = kSequence / "boxes.txt";
  options.project_root = SP_SOURCE_DIR;
  options.load_map = load;
  options.save_map = save;
  return run_slam(source, config, options);
}

// Ground truth at `stamp` (nearest entry within 10 ms).
const io::StampedPose* nearest(const std::vector<io::StampedPose>& gt, double stamp) {
  const io::StampedPose* best = nullptr;
  for (const auto& p : gt) {
    if (std::abs(p.stamp - stamp) < 0.01 &&
        (best == nullptr || std::abs(p.stamp - stamp) < std::abs(best->stamp - stamp)))
      best = &p;
  }
  return best;
}

geo::SE3 to_se3(const io::StampedPose& p) { return {p.q, p.t}; }

struct FrameCheck {
  double unaligned_rmse = 0;  // m, against ground truth in the first run's frame, no alignment
  double moved = 0;           // m, largest ground-truth distance from the first run's first frame
};

// The map's world is the camera of the first run's first frame (it starts at the identity), so ground
// truth relative to that frame is directly comparable with a continuation's poses.
FrameCheck check_in_first_frame(const std::filesystem::path& first_trajectory_file,
                                const std::filesystem::path& trajectory_file) {
  const auto gt = io::read_tum_trajectory(*io::TumSequence(kSequence).groundtruth_path());
  const auto first = io::read_tum_trajectory(first_trajectory_file);
  const auto est = io::read_tum_trajectory(trajectory_file);
  FrameCheck c;
  if (first.empty() || est.empty()) return {1e9, 0};
  const io::StampedPose* gt0 = nearest(gt, first.front().stamp);
  if (gt0 == nullptr) return {1e9, 0};
  const geo::SE3 T_0w = to_se3(*gt0).inverse();
  double sum_sq = 0;
  for (const auto& p : est) {
    const io::StampedPose* g = nearest(gt, p.stamp);
    if (g == nullptr) return {1e9, 0};
    const Eigen::Vector3d truth = (T_0w * to_se3(*g)).translation();
    sum_sq += (truth - p.t).squaredNorm();
    c.moved = std::max(c.moved, truth.norm());
  }
  c.unaligned_rmse = std::sqrt(sum_sq / static_cast<double>(est.size()));
  return c;
}

TEST(MapReuse, SecondRunRelocalisesInTheSavedMapAndContinuesInItsFrame) {
  SP_REQUIRE_SHARED(kSequence);
  const auto dir = scratch("reuse");
  const auto map_file = dir / "office_a.spmap";

  // 1. Map the first part and save it.
  const RunResult first = run_part(0, kSplit, dir / "first", std::nullopt, map_file);
  ASSERT_TRUE(first.completed);
  ASSERT_TRUE(std::filesystem::exists(map_file));
  ASSERT_TRUE(first.stats.contains("map_saved"));
  const std::size_t saved_keyframes = first.stats["map_saved"]["keyframes"].get<std::size_t>();
  const std::size_t saved_points = first.stats["map_saved"]["points"].get<std::size_t>();
  EXPECT_GT(saved_keyframes, 3U);
  EXPECT_GT(saved_points, 300U);
  const auto first_trajectory = io::read_tum_trajectory(dir / "first" / "trajectory.txt");
  ASSERT_FALSE(first_trajectory.empty());
  // The first run starts its map at the identity on its first frame: that frame is the map's world.
  EXPECT_LT(first_trajectory.front().t.norm(), 1e-9);

  // 2. Loading keeps every keyframe id and pose as saved.
  const map::MapContents contents = map::read_map_file(map_file);
  ASSERT_EQ(contents.keyframes.size(), saved_keyframes);
  {
    io::TumSequence source(kSequence);
    SystemOptions options;
    options.deterministic = true;
    options.project_root = SP_SOURCE_DIR;
    SystemConfig config = SystemConfig::load(kConfig);
    config.dynamic.mode = "off";  // only the loaded map is checked: no detector to load
    SlamSystem system(config, source.camera(), options);
    system.load_map(map_file);
    const auto keyframes = system.keyframe_trajectory();  // live keyframes in id order
    ASSERT_EQ(keyframes.size(), contents.keyframes.size());
    for (std::size_t i = 0; i < keyframes.size(); ++i) {
      const geo::SE3 T_wc = contents.keyframes[i].T_cw.inverse();
      EXPECT_EQ(keyframes[i].stamp, contents.keyframes[i].stamp);
      EXPECT_LT((keyframes[i].t - T_wc.translation()).norm(), 1e-12);
    }
    const auto first_keyframes = io::read_tum_trajectory(dir / "first" / "keyframes.txt");
    ASSERT_EQ(first_keyframes.size(), keyframes.size());
    for (std::size_t i = 0; i < keyframes.size(); ++i)
      EXPECT_LT((first_keyframes[i].t - keyframes[i].t).norm(), 1e-5);  // text precision
  }

  // 3. Continue on the last frames with the loaded map.
  const RunResult second = run_part(kSplit, 150 - kSplit, dir / "second", map_file, std::nullopt);
  ASSERT_TRUE(second.completed);
  const auto& loaded = second.stats["map_loaded"];
  EXPECT_EQ(loaded["keyframes"].get<std::size_t>(), saved_keyframes);
  EXPECT_EQ(loaded["points"].get<std::size_t>(), saved_points);
  ASSERT_FALSE(loaded["first_relocalization_frame"].is_null());
  const auto first_reloc = loaded["first_relocalization_frame"].get<std::size_t>();
  EXPECT_GE(first_reloc, kSplit);
  EXPECT_LE(first_reloc, kSplit + 5);
  EXPECT_LE(second.stats["lost_frames"].get<std::size_t>(), 5U);
  EXPECT_GE(second.stats["tracked_frames"].get<std::size_t>(), 150 - kSplit - 5);
  EXPECT_GE(second.stats["keyframes"].get<std::size_t>(), saved_keyframes / 2);  // extended, not replaced
  ASSERT_TRUE(second.ate_rmse.has_value());
  EXPECT_LT(*second.ate_rmse, 0.02);

  // 4. No re-initialisation: the second run's poses are in the first run's frame, so they match the
  // ground truth relative to the first run's first frame WITHOUT any alignment.
  const auto second_trajectory = io::read_tum_trajectory(dir / "second" / "trajectory.txt");
  ASSERT_GE(second_trajectory.size(), 40U);
  const FrameCheck c =
      check_in_first_frame(dir / "first" / "trajectory.txt", dir / "second" / "trajectory.txt");
  RecordProperty("unaligned_rmse_mm", static_cast<int>(1000 * c.unaligned_rmse));
  EXPECT_GT(c.moved, 0.2);  // so the check below can tell a restart at the identity from a continuation
  EXPECT_LT(c.unaligned_rmse, 0.03);

  // 5. Back at the start of the sequence with few recent-keyframe candidates: the BoW database over
  // the loaded keyframes has to find the early keyframes (the recent ones were taken ~0.3 m away).
  const RunResult again = run_part(0, 40, dir / "again", map_file, std::nullopt,
                                   [](SystemConfig& c) { c.tracker.relocalization_candidates = 2; });
  ASSERT_TRUE(again.completed);
  EXPECT_EQ(again.stats["map_loaded"]["relocalization_candidates"].get<std::string>(), "bow");
  ASSERT_FALSE(again.stats["map_loaded"]["first_relocalization_frame"].is_null());
  EXPECT_LE(again.stats["map_loaded"]["first_relocalization_frame"].get<std::size_t>(), 5U);
  const FrameCheck c2 =
      check_in_first_frame(dir / "first" / "trajectory.txt", dir / "again" / "trajectory.txt");
  RecordProperty("unaligned_rmse_again_mm", static_cast<int>(1000 * c2.unaligned_rmse));
  EXPECT_LT(c2.unaligned_rmse, 0.03);

  // 6. Without a vocabulary the candidates are all keyframes ranked by thumbnail similarity.
  const RunResult plain = run_part(0, 30, dir / "plain", map_file, std::nullopt, [](SystemConfig& c) {
    c.loop.detector = "off";
    c.loop.vocabulary = "does/not/exist.spv";
    c.tracker.relocalization_candidates = 2;
  });
  ASSERT_TRUE(plain.completed);
  EXPECT_EQ(plain.stats["map_loaded"]["relocalization_candidates"].get<std::string>(), "thumbnail");
  ASSERT_FALSE(plain.stats["map_loaded"]["first_relocalization_frame"].is_null());
  EXPECT_LE(plain.stats["map_loaded"]["first_relocalization_frame"].get<std::size_t>(), 5U);
  const FrameCheck c3 =
      check_in_first_frame(dir / "first" / "trajectory.txt", dir / "plain" / "trajectory.txt");
  EXPECT_LT(c3.unaligned_rmse, 0.03);
}

TEST(MapReuse, DamagedMapIsRefusedBeforeTheFirstFrame) {
  SP_REQUIRE_SHARED(kSequence);
  const auto dir = scratch("damaged");
  const auto file = dir / "not_a_map.spmap";
  {
    std::ofstream out(file);
    out << "this is not a map\n";
  }
  try {
    run_part(0, 5, dir / "out", file, std::nullopt);
    ADD_FAILURE() << "a damaged map was accepted";
  } catch (const stillpoint::Error& e) {  // run_slam loads it through the public API
    EXPECT_NE(std::string(e.what()).find("not a StillPoint map file"), std::string::npos) << e.what();
    EXPECT_EQ(e.file(), file.string());
  }
}

}  // namespace
}  // namespace sp::pipeline
