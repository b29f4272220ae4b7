#pragma once
// `stillpoint run`'s job: drives a stillpoint::System (the public API, with system_access.hpp for
// what only the CLI needs) over a frame source and writes what a user expects in OUT: the trajectory
// of every frame (TUM and KITTI), the keyframe trajectory, stats.json, and, with ground truth, ATE/RPE
// and a plot. Outputs are written also when the run stops early (error, Ctrl-C).
#include <atomic>
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "stillpoint/io/frame_source.hpp"
#include "stillpoint/pipeline/system_config.hpp"
#include "stillpoint/stillpoint.hpp"

namespace sp::api {

struct RunOptions {
  std::filesystem::path out_dir;
  bool deterministic = false;
  bool progress = true;
  std::optional<std::filesystem::path> groundtruth;
  std::optional<std::filesystem::path> boxes_file;  // for oracle culling
  std::optional<std::filesystem::path> masks_dir;   // for scoring culling
  std::filesystem::path project_root = ".";         // where relative resource paths resolve
  const std::atomic<bool>* stop = nullptr;          // set asynchronously (SIGINT) to end the run early
  std::string label;                                // shown in the progress bar
  nlohmann::json extra_stats;                       // merged into stats.json (mode switches etc.)
  std::optional<std::filesystem::path> load_map;    // relocalise in this saved map and extend it
  std::optional<std::filesystem::path> save_map;    // save the map here at the end (also on early stop)
  bool artifacts = true;     // map_points.ply and culled/ thumbnails (run_artifacts.hpp)
  bool dense_cloud = false;  // also dense_cloud.ply from keyframe depth, dynamic regions removed
  // Every this many frames the current RSS goes into stats.json as rss_timeline_mib, a list of
  // [frames done, MiB] (plus one sample after the stages have drained); 0 = off. scripts/soak.sh
  // reads it to check that memory stays flat over a long run.
  std::size_t rss_every_frames = 100;
  // Frames are handed to SLAM no earlier than their recorded time, scaled: 1 plays a sequence back like
  // the live camera that recorded it (what ORB-SLAM's and NGD-SLAM's TUM examples do: the threads
  // then share the CPU as on a robot), 2 twice as fast; 0 = as fast as the system goes. A frame that
  // is due while the previous one is still being tracked is processed at once, never dropped.
  double playback_rate = 0;
  // Called on the tracking thread after each frame (the live view, `run --viewer`); an exception
  // from it is logged and the observer dropped, the run goes on.
  std::function<void(const io::FrameData&, const stillpoint::TrackResult&, stillpoint::System&)> on_frame;
  // Called once after the stages have drained, before the outputs are written.
  std::function<void(stillpoint::System&)> on_finish;
};

struct RunResult {
  nlohmann::json stats;
  bool completed = false;   // false when stopped early or a stage failed
  std::string stop_reason;  // why it stopped early (the error, or "stop requested"); empty when completed
  std::optional<double> ate_rmse;
};

RunResult run_slam(io::FrameSource& source, const pipeline::SystemConfig& config, const RunOptions& options);

}  // namespace sp::api
