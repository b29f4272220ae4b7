#include "stillpoint/api/runner.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <fstream>

#include "stillpoint/api/system_access.hpp"
#include "stillpoint/common/atomic_file.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/common/progress_bar.hpp"
#include "stillpoint/common/timing.hpp"
#include "stillpoint/eval/evaluate.hpp"
#include "stillpoint/eval/loop_check.hpp"
#include "stillpoint/eval/missing_frames.hpp"
#include "stillpoint/pipeline/slam_system.hpp"

namespace sp::api {

using stillpoint::internal::SystemAccess;

namespace {

void write_json(const std::filesystem::path& file, const nlohmann::json& j) {
  write_file_atomically(file, j.dump(2) + "\n");
}

// Every closed loop judged by ground truth (loops_true / loops_false and one record per loop).
void check_loops_against(const std::vector<io::StampedPose>& gt,
                         const std::vector<loop::LoopClosure>& closures, nlohmann::json& stats) {
  if (closures.empty() && !stats.contains("loops_closed")) return;
  std::size_t n_true = 0, n_false = 0;
  nlohmann::json list = nlohmann::json::array();
  for (const auto& c : closures) {
    const auto check = eval::check_loop(gt, c.query_stamp, c.match_stamp, c.T_query_match);
    nlohmann::json j = {
        {"query_stamp", c.query_stamp}, {"match_stamp", c.match_stamp}, {"inliers", c.inliers}};
    if (check) {
      j["translation_error_m"] = check->translation_error_m;
      j["rotation_error_deg"] = check->rotation_error_deg;
      j["gt_distance_m"] = check->gt_distance_m;
      j["true"] = check->is_true;
      (check->is_true ? n_true : n_false)++;
      if (!check->is_true)
        spdlog::warn("false loop closure: {:.3f} -> {:.3f} is off by {:.2f} m / {:.1f} deg", c.query_stamp,
                     c.match_stamp, check->translation_error_m, check->rotation_error_deg);
    }
    list.push_back(j);
  }
  stats["loop_closures"] = list;
  stats["loops_true"] = n_true;
  stats["loops_false"] = n_false;
}

// trajectory.txt stays plain TUM (evo reads it); the map of each of its lines is in this side file.
void write_trajectory_maps(const std::filesystem::path& file,
                           const std::vector<std::pair<double, std::uint32_t>>& maps) {
  std::ofstream out(file);
  if (!out) throw Error("cannot write " + file.string());
  out << "# timestamp map_id (0: the first map or one merged into it; other: a map never merged, own "
         "frame)\n";
  for (const auto& [stamp, m] : maps) out << fmt::format("{:.6f} {}\n", stamp, m);
}

// trajectory.txt leaves lost frames out; this one has a pose for every frame given, the lost ones
// interpolated across their gap (held at the end or between maps), the rule `stillpoint eval
// --fill-missing interpolate` applies to any system's file. How many were filled goes into stats.json.
std::vector<io::StampedPose> write_every_frame_trajectory(
    const std::filesystem::path& file, const std::vector<double>& frame_stamps,
    const std::vector<io::StampedPose>& trajectory, const std::vector<std::pair<double, std::uint32_t>>& maps,
    nlohmann::json& stats) {
  std::vector<std::uint32_t> map_ids;
  for (const auto& m : maps) map_ids.push_back(m.second);
  const auto filled =
      eval::fill_missing_frames(frame_stamps, trajectory, eval::MissingFrames::Interpolate, map_ids);
  io::write_tum_trajectory(file, filled.poses);
  stats["every_frame"] = eval::to_json(filled, frame_stamps.size());
  return filled.poses;
}

void write_outputs(stillpoint::System& system, const RunOptions& options, const nlohmann::json& run_stats,
                   const std::vector<double>& frame_stamps, RunResult& result) {
  std::filesystem::create_directories(options.out_dir);
  system.save_trajectory(options.out_dir / "trajectory.txt", stillpoint::TrajectoryFormat::Tum);
  // trajectory_kitti.txt and its timestamps, trajectory_kitti_times.txt
  system.save_trajectory(options.out_dir / "trajectory_kitti.txt", stillpoint::TrajectoryFormat::Kitti);
  system.save_keyframe_trajectory(options.out_dir / "keyframes.txt");
  // The evaluation reads the pipeline's own poses (quaternions as estimated, not re-derived from the
  // API's rotation matrices), so its figures stay those of the files above.
  pipeline::SlamSystem& slam = SystemAccess::pipeline(system);
  const auto trajectory = slam.trajectory();
  const auto trajectory_maps = slam.trajectory_maps();
  write_trajectory_maps(options.out_dir / "trajectory_maps.txt", trajectory_maps);
  result.stats = slam.statistics();
  std::vector<io::StampedPose> every_frame;
  try {
    every_frame = write_every_frame_trajectory(options.out_dir / "trajectory_every_frame.txt", frame_stamps,
                                               trajectory, trajectory_maps, result.stats);
  } catch (const std::exception& e) {
    spdlog::warn("trajectory_every_frame.txt not written: {}", e.what());
  }
  if (!result.stats["unmerged_maps"].empty()) {
    spdlog::warn(
        "maps {} were never merged into map 0: their frames in trajectory.txt are in their own frames "
        "(trajectory_maps.txt names each frame's map)",
        result.stats["unmerged_maps"].dump());
  }
  result.stats["completed"] = result.completed;
  // A batch script that discards the log still learns why a run stopped early.
  if (!result.stop_reason.empty()) result.stats["stop_reason"] = result.stop_reason;
  for (const auto& [k, v] : options.extra_stats.items()) result.stats[k] = v;
  for (const auto& [k, v] : run_stats.items()) result.stats[k] = v;
  try {
    const nlohmann::json artifacts = slam.write_artifacts();
    if (!artifacts.empty()) result.stats["artifacts"] = artifacts;
  } catch (const std::exception& e) {
    spdlog::warn("run artifacts (PLY, thumbnails) not written: {}", e.what());
  }
  if (options.groundtruth && trajectory.size() >= 3) {
    try {
      const auto gt = io::read_tum_trajectory(*options.groundtruth);
      const auto ev = eval::evaluate(gt, trajectory, eval::EvalOptions{});
      result.stats["eval"] = eval::to_json(ev);
      result.ate_rmse = ev.ate.rmse;
      eval::write_plot(options.out_dir / "trajectory.png", ev);
      check_loops_against(gt, slam.loop_closures(), result.stats);
      // Scored on every frame, as systems that write a pose for each are (NGD-SLAM, ORB-SLAM3).
      if (!every_frame.empty()) {
        const auto ev_all = eval::evaluate(gt, every_frame, eval::EvalOptions{});
        result.stats["every_frame"]["ate_rmse_m"] = ev_all.ate.rmse;
        result.stats["every_frame"]["ate_max_m"] = ev_all.ate.max;
        result.stats["every_frame"]["pairs"] = ev_all.pairs;
      }
    } catch (const Error& e) {
      spdlog::warn("evaluation skipped: {}", e.what());
    }
  }
  write_json(options.out_dir / "stats.json", result.stats);
}

}  // namespace

RunResult run_slam(io::FrameSource& source, const pipeline::SystemConfig& config, const RunOptions& options) {
  RunResult result;
  pipeline::SystemOptions system_options;
  system_options.deterministic = options.deterministic;
  system_options.boxes_file = options.boxes_file;
  system_options.masks_dir = options.masks_dir;
  system_options.project_root = options.project_root;
  if (options.artifacts) {
    system_options.artifacts.out_dir = options.out_dir;
    system_options.artifacts.expected_frames = source.size_hint();
    system_options.artifacts.dense_cloud = options.dense_cloud;
  }
  stillpoint::System system = SystemAccess::create(config, source.camera(), system_options);
  pipeline::SlamSystem& slam = SystemAccess::pipeline(system);
  if (options.load_map) system.load_map(*options.load_map);
  ProgressBar bar(options.label.empty() ? "tracking" : options.label, source.size_hint(), options.progress);
  Stopwatch wall;
  PlaybackClock pace(options.playback_rate);
  std::size_t done = 0;
  std::size_t lost = 0;
  std::vector<double> frame_stamps;  // every frame given, tracked or not
  bool interrupted = false;
  nlohmann::json rss_timeline = nlohmann::json::array();  // [frames done, current RSS MiB]
  auto on_frame = options.on_frame;
  try {
    while (true) {
      if (options.stop != nullptr && options.stop->load()) {
        spdlog::warn("stop requested: finishing and writing the trajectory so far");
        interrupted = true;
        result.stop_reason = "stop requested";
        break;
      }
      Stopwatch load;
      auto data = source.next();
      slam.times().add("load", load.elapsed_ms());
      if (!data) break;
      if (options.playback_rate > 0) pace.wait_for(data->stamp);
      frame_stamps.push_back(data->stamp);
      const stillpoint::TrackResult tracked = SystemAccess::track(system, *data);
      if (on_frame) {
        try {
          on_frame(*data, tracked, system);
        } catch (const std::exception& e) {
          spdlog::warn("frame observer failed, dropped: {}", e.what());
          on_frame = nullptr;
        }
      }
      if (tracked.state == stillpoint::TrackingState::Lost) ++lost;
      ++done;
      if (options.rss_every_frames != 0 && done % options.rss_every_frames == 0) {
        rss_timeline.push_back({done, current_rss_mib()});
      }
      if (slam.failed()) throw Error("a pipeline stage failed: " + slam.failure());
      const double fps = static_cast<double>(done) / std::max(1e-9, wall.elapsed_ms() / 1000.0);
      bar.update(done, fmt::format("{:.1f} fps, {} lost", fps, lost));
    }
    result.completed = !interrupted;
  } catch (const std::exception& e) {
    spdlog::error("run stopped at frame {}: {}", done, e.what());
    result.completed = false;
    result.stop_reason = fmt::format("stopped at frame {}: {}", done, e.what());
  }
  bar.finish();
  system.shutdown();
  if (options.on_finish) {
    try {
      options.on_finish(system);
    } catch (const std::exception& e) {
      spdlog::warn("finish observer failed: {}", e.what());
    }
  }
  if (options.rss_every_frames != 0) rss_timeline.push_back({done, current_rss_mib()});
  if (options.save_map) {
    // After finish(): local mapping and loop closing have drained, so the map is final.
    try {
      system.save_map(*options.save_map);
    } catch (const std::exception& e) {
      spdlog::error("map not saved: {}", e.what());
      result.completed = false;
      if (result.stop_reason.empty()) result.stop_reason = std::string("map not saved: ") + e.what();
    }
  }
  const double seconds = wall.elapsed_ms() / 1000.0;
  const nlohmann::json run_stats = {{"wall_s", seconds},
                                    {"fps", static_cast<double>(done) / std::max(1e-9, seconds)},
                                    {"skipped_frames", source.skipped_frames()},
                                    {"rss_timeline_mib", rss_timeline}};
  write_outputs(system, options, run_stats, frame_stamps, result);
  return result;
}

}  // namespace sp::api
