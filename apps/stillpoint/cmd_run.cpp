// stillpoint run: SLAM over a TUM-format sequence (or the bundled demo sequence).
#include <fmt/format.h>
#include <signal.h>
#include <spdlog/spdlog.h>

#include <atomic>
#include <filesystem>
#include <thread>

#include "commands.hpp"
#include "stillpoint/api/runner.hpp"
#include "stillpoint/common/data_dir.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/io/camera_config.hpp"
#include "stillpoint/io/openni2_source.hpp"
#include "stillpoint/io/tum_sequence.hpp"
#include "stillpoint/loop/loop_detector.hpp"
#include "stillpoint/pipeline/slam_system.hpp"
#include "stillpoint/stillpoint.hpp"
#ifdef SP_HAVE_LIVE_VIEW
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "stillpoint/report/live_view.hpp"
#endif

namespace sp::app {

namespace {

// SIGINT is blocked in every thread and collected by one watcher thread with sigtimedwait, so no
// global flag or async-signal handler is needed; the run sees an ordinary atomic owned by main.
class InterruptWatcher {
 public:
  InterruptWatcher() {
    sigemptyset(&set_);
    sigaddset(&set_, SIGINT);
    sigaddset(&set_, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &set_, nullptr);
    thread_ = std::thread([this] {
      const timespec timeout{0, 100'000'000};
      while (!done_.load()) {
        if (sigtimedwait(&set_, nullptr, &timeout) > 0) stop_ = true;
      }
    });
  }
  ~InterruptWatcher() {
    done_ = true;
    thread_.join();
    pthread_sigmask(SIG_UNBLOCK, &set_, nullptr);
  }
  InterruptWatcher(const InterruptWatcher&) = delete;
  InterruptWatcher& operator=(const InterruptWatcher&) = delete;
  [[nodiscard]] const std::atomic<bool>& flag() const { return stop_; }

 private:
  sigset_t set_{};
  std::atomic<bool> stop_{false};
  std::atomic<bool> done_{false};
  std::thread thread_;
};

struct RunArgs {
  std::string dataset;
  std::string config;
  std::string camera;
  std::string camera_config;
  std::string out = "stillpoint_out";
  bool deterministic = false;
  bool no_progress = false;
  std::size_t max_frames = 0;
  std::string dynamic;
  std::string detector_model;
  std::string keyframe_policy;
  std::string loop_detector;
  std::string save_map;
  std::string load_map;
  bool dense_cloud = false;
  std::vector<std::string> overrides;  // --set section.key=value
  int viewer_port = -1;                // --viewer [PORT]; -1 = no live view
  double playback_rate = 0;            // --playback-rate / --realtime; 0 = as fast as possible
};

// The data folder (config/, data/, models/) of this binary: $STILLPOINT_DATA_DIR, else share/stillpoint
// beside the installed binary (or the build tree's link to the source tree), see common/data_dir.hpp.
std::filesystem::path data_dir() { return resolve_data_dir(current_executable()); }

#ifdef SP_HAVE_LIVE_VIEW
std::string floats_base64(const std::vector<float>& v) {
  return report::base64_encode(
      std::string_view(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(float)));
}

// The map (up to 30000 points) and the keyframe positions, as one "map" event.
void publish_map(report::LiveViewServer& server, stillpoint::System& system) {
  std::vector<float> points, keyframes;
  for (const auto& p : system.map_points(30000)) points.insert(points.end(), {p.x(), p.y(), p.z()});
  for (const auto& k : system.keyframe_trajectory()) {
    const Eigen::Vector3d& t = k.T_world_camera.translation();
    keyframes.insert(keyframes.end(),
                     {static_cast<float>(t.x()), static_cast<float>(t.y()), static_cast<float>(t.z())});
  }
  server.publish("map", nlohmann::json{{"points", floats_base64(points)},
                                       {"count", points.size() / 3},
                                       {"keyframes", floats_base64(keyframes)},
                                       {"keyframe_count", keyframes.size() / 3}}
                            .dump());
}

// Streams the run to a LiveViewServer (report/live_view.hpp): every pose, the map and keyframes after
// each keyframe (and every 30 frames), the frame with its culled features every 3rd frame.
void attach_live_view(report::LiveViewServer& server, api::RunOptions& options) {
  options.on_frame = [&server, frames = std::size_t{0}](const io::FrameData& f,
                                                        const stillpoint::TrackResult& r,
                                                        stillpoint::System& system) mutable {
    ++frames;
    nlohmann::json pose = {{"frame", f.index},
                           {"t", f.stamp},
                           {"state", stillpoint::to_string(r.state)},
                           {"culled", r.culled_features}};
    if (r.has_pose) {
      const Eigen::Vector3d& t = r.T_world_camera.translation();
      const Eigen::Quaterniond q(r.T_world_camera.rotation());
      pose["p"] = {t.x(), t.y(), t.z()};
      pose["q"] = {q.x(), q.y(), q.z(), q.w()};
    }
    server.publish("pose", pose.dump());
    if (server.clients() == 0) return;  // the rest is only worth its cost when someone watches
    if (r.keyframe || frames % 30 == 0) publish_map(server, system);
    if (frames % 3 == 1 && !f.bgr.empty()) {
      cv::Mat small;
      const double scale = 320.0 / f.bgr.cols;
      cv::resize(f.bgr, small, cv::Size(), scale, scale, cv::INTER_AREA);
      for (const cv::Point2f& p : r.culled_points)
        cv::circle(small, p * scale, 2, cv::Scalar(0, 0, 255), cv::FILLED);
      std::vector<unsigned char> jpeg;
      cv::imencode(".jpg", small, jpeg, {cv::IMWRITE_JPEG_QUALITY, 70});
      server.publish("overlay",
                     nlohmann::json{{"jpeg", report::base64_encode(std::string_view(
                                                 reinterpret_cast<const char*>(jpeg.data()), jpeg.size()))},
                                    {"culled", r.culled_features}}
                         .dump());
    }
  };
  options.on_finish = [&server](stillpoint::System& system) {
    publish_map(server, system);
    const auto stats = nlohmann::json::parse(system.statistics_json());
    server.publish("end", nlohmann::json{{"frames", stats.value("frames", 0)},
                                         {"tracked", stats.value("tracked_frames", 0)}}
                              .dump());
  };
}
#endif

// Which of the paper's parts ran: culling mode and detector model, keyframe policy, loop detector.
void print_methods(const nlohmann::json& s) {
  const std::string mode = s.value("dynamic_mode", std::string("?"));
  const std::string model = s.value("detector_model", std::string());
  const std::string detector = model.empty() ? std::string("no detector")
                                             : "detector " + std::filesystem::path(model).filename().string();
  fmt::print("culling: {} ({}), {} features culled ({:.1f}/frame)\n", mode, detector,
             s.value("culled_features_total", 0), s.value("culled_features_per_frame", 0.0));
  std::string rules;
  if (s.contains("keyframe_rules")) {
    for (const auto& [rule, n] : s["keyframe_rules"].items()) {
      const std::string key = rule;
      if (key == "decisions" || key == "inserted" || key.rfind("any_", 0) == 0 ||
          key.rfind("threshold", 0) == 0 || !n.is_number() || n.get<long>() == 0)
        continue;
      rules += fmt::format("{}{} {}", rules.empty() ? "" : ", ", key, n.get<long>());
    }
  }
  fmt::print("keyframes: {} policy{}\n", s.value("keyframe_policy", std::string("?")),
             rules.empty() ? std::string() : " (" + rules + ")");
  const std::string loop = s.value("loop_detector", std::string("off"));
  if (loop == "off") {
    fmt::print("loop detection: off\n");
  } else {
    fmt::print("loop detection: {} ({} queries, {} loops detected, {} closed)\n", loop,
               s.value("loop_queries", 0), s.value("loops_detected", 0), s.value("loops_closed", 0));
  }
}

int run(const RunArgs& args) {
  const std::filesystem::path data = data_dir();
  const std::filesystem::path dataset = args.dataset.empty() ? data / "data" / "demo" / "walking_xyz_demo"
                                                             : std::filesystem::path(args.dataset);
  if (args.dataset.empty())
    spdlog::info("no --dataset given: running the bundled demo sequence {}", dataset.string());
  const std::filesystem::path config_file =
      args.config.empty() ? data / "config" / "stillpoint.yaml" : std::filesystem::path(args.config);
  pipeline::SystemConfig config = pipeline::SystemConfig::load(config_file, args.overrides);
  if (!args.dynamic.empty()) config.dynamic.mode = args.dynamic;
  // A model given on the command line is the user's file: relative to the working directory (the
  // configuration's own relative paths resolve against the project root).
  if (!args.detector_model.empty())
    config.dynamic.model = std::filesystem::absolute(args.detector_model).lexically_normal().string();
  if (!args.keyframe_policy.empty()) config.tracker.keyframes.policy = args.keyframe_policy;
  if (!args.loop_detector.empty()) config.loop.detector = args.loop_detector;
  if (loop::needs_place_model(config.loop.detector) && !stillpoint::has_netvlad())
    throw Error(pipeline::netvlad_unavailable_message(config.loop.detector));
  InterruptWatcher interrupt;  // before any thread starts, so all threads inherit the blocked mask
  std::unique_ptr<io::FrameSource> source;
  std::optional<std::filesystem::path> groundtruth;
  if (args.camera == "openni2") {
    // Live camera: intrinsics from --camera-config, else from the device's field of view.
    io::OpenNI2Options live;
    if (!args.camera_config.empty()) live.camera = io::load_camera_config(args.camera_config);
    source = io::open_openni2_camera(live);
  } else {
    io::TumSequenceOptions seq_options;
    if (!args.camera.empty()) seq_options.camera_file = args.camera;
    seq_options.max_frames = args.max_frames;
    auto sequence = std::make_unique<io::TumSequence>(dataset, seq_options);
    groundtruth = sequence->groundtruth_path();
    source = std::move(sequence);
  }

  api::RunOptions options;
  options.out_dir = args.out;
  options.deterministic = args.deterministic;
  options.progress = !args.no_progress;
  options.groundtruth = groundtruth;
  options.boxes_file = dataset / "boxes.txt";
  options.masks_dir = dataset / "masks";
  options.project_root = data;  // relative paths the configuration's folder does not hold
  options.stop = &interrupt.flag();
  options.label = dataset.filename().string();
  if (!args.load_map.empty()) options.load_map = args.load_map;
  if (!args.save_map.empty()) options.save_map = args.save_map;
  options.dense_cloud = args.dense_cloud;
  if (args.camera != "openni2") options.playback_rate = args.playback_rate;  // a live camera paces itself
  if (options.playback_rate > 0) options.extra_stats["playback_rate"] = options.playback_rate;
#ifdef SP_HAVE_LIVE_VIEW
  std::unique_ptr<report::LiveViewServer> live;
  if (args.viewer_port >= 0) {
    live = std::make_unique<report::LiveViewServer>(args.viewer_port, report::viewer_assets());
    attach_live_view(*live, options);
    fmt::print("live view: http://127.0.0.1:{}/ (open it in a browser; Ctrl-C stops the run)\n",
               live->port());
    std::fflush(stdout);
  }
#else
  if (args.viewer_port >= 0) throw Error("--viewer: this stillpoint was built without the report module");
#endif
  options.extra_stats["dataset"] = dataset.string();
  options.extra_stats["config"] = config_file.string();
  if (!args.overrides.empty()) options.extra_stats["config_overrides"] = args.overrides;
  const auto result = api::run_slam(*source, config, options);

  const auto& s = result.stats;
  fmt::print("\n== StillPoint run: {} ==\n", dataset.filename().string());
  fmt::print("frames {} (tracked {}, lost {}), keyframes {}, map points {}, {:.1f} fps\n",
             s.value("frames", 0), s.value("tracked_frames", 0), s.value("lost_frames", 0),
             s.value("keyframes", 0), s.value("map_points", 0), s.value("fps", 0.0));
  if (s.contains("stages_ms") && s["stages_ms"].contains("frame")) {
    fmt::print("tracking thread: median {:.1f} ms/frame, p95 {:.1f} ms\n",
               s["stages_ms"]["frame"].value("median_ms", 0.0), s["stages_ms"]["frame"].value("p95_ms", 0.0));
  }
  print_methods(s);
  if (result.ate_rmse) {
    const auto& e = s["eval"];
    fmt::print("ATE RMSE {:.4f} m | RPE trans RMSE {:.4f} m, rot RMSE {:.3f} deg (delta 1 s)\n",
               *result.ate_rmse, e["rpe_trans"].value("rmse", 0.0), e["rpe_rot_deg"].value("rmse", 0.0));
    // stats is const: operator[] on a missing key would be undefined, so look before reading.
    if (s.contains("every_frame") && s["every_frame"].contains("ate_rmse_m") &&
        s.value("lost_frames", 0) > 0) {
      fmt::print("ATE RMSE on every frame {:.4f} m (lost frames interpolated, trajectory_every_frame.txt)\n",
                 s["every_frame"].value("ate_rmse_m", 0.0));
    }
  }
  fmt::print(
      "outputs: {}/trajectory.txt (TUM; trajectory_kitti.txt: KITTI; trajectory_every_frame.txt: lost frames "
      "filled), keyframes.txt, stats.json, "
      "map_points.ply{}{}, culled/\n",
      args.out, args.dense_cloud ? ", dense_cloud.ply" : "", result.ate_rmse ? ", trajectory.png" : "");
  if (s.contains("map_loaded")) {
    const auto& m = s["map_loaded"];
    fmt::print("map loaded: {} keyframes, {} points; first relocalised frame: {}\n", m.value("keyframes", 0),
               m.value("points", 0),
               m["first_relocalization_frame"].is_null() ? std::string("none")
                                                         : m["first_relocalization_frame"].dump());
  }
  if (s.contains("map_saved")) {
    const auto& m = s["map_saved"];
    fmt::print("map saved: {} ({} keyframes, {} points, {:.1f} MB)\n", m.value("file", std::string()),
               m.value("keyframes", 0), m.value("points", 0), m.value("bytes", 0.0) / 1e6);
  }
  return result.completed ? 0 : 1;
}

}  // namespace

void add_run_command(CLI::App& app) {
  auto args = std::make_shared<RunArgs>();
  CLI::App* cmd =
      app.add_subcommand("run", "Run SLAM on a TUM-format RGB-D sequence (default: the bundled demo)");
  cmd->add_option("--dataset", args->dataset, "Sequence folder in TUM RGB-D layout (default: bundled demo)");
  cmd->add_option("--config", args->config, "System configuration YAML (default: config/stillpoint.yaml)");
  cmd->add_option(
      "--camera", args->camera,
      "Camera YAML: ours, ORB-SLAM2/3 or stella_vslam settings (default: DATASET/camera.yaml), or "
      "'openni2' for a live RGB-D camera");
  cmd->add_option("--camera-config", args->camera_config,
                  "Intrinsics YAML for a live camera (default: from its FOV)");
  cmd->add_option("--out", args->out, "Output folder")->capture_default_str();
  cmd->add_flag("--deterministic", args->deterministic,
                "Fixed seeds, stages in lock-step: identical output twice");
  cmd->add_option("--max-frames", args->max_frames, "Stop after this many frames (0 = all)");
  cmd->add_option("--playback-rate", args->playback_rate,
                  "Hand frames to SLAM at this multiple of their recorded pace, like a live camera (1 = "
                  "real time; late frames are processed at once, never dropped; 0 = as fast as possible)")
      ->check(CLI::Range(0.0, 1000.0));
  cmd->add_flag_callback(
      "--realtime", [args] { args->playback_rate = 1.0; }, "Same as --playback-rate 1");
  cmd->add_flag("--no-progress", args->no_progress, "No progress bar");
  cmd->add_flag("--dense-cloud", args->dense_cloud,
                "Also write dense_cloud.ply from keyframe depth (dynamic regions removed)");
  cmd->add_option("--dynamic", args->dynamic, "Dynamic culling: off|flow|detector|detector+flow|oracle|auto")
      ->check(CLI::IsMember({"off", "flow", "detector", "detector+flow", "oracle", "auto"}));
  cmd->add_option("--detector-model", args->detector_model,
                  "YOLO model (.onnx, or Darknet .cfg with .weights)");
  cmd->add_option(
         "--loop-detector", args->loop_detector,
         "Loop detection: off|bow-keyframe|bow-sequence|netvlad|hybrid (BoW re-ranked by ParC_NetVLAD)")
      ->check(CLI::IsMember({"off", "bow-keyframe", "bow-sequence", "netvlad", "hybrid"}));
  cmd->add_option("--save-map", args->save_map, "Save the map to this file at the end (docs/map_files.md)");
  cmd->add_option("--load-map", args->load_map,
                  "Relocalise in this saved map and extend it (instead of starting a new map)");
  cmd->add_option("--set", args->overrides,
                  "Override a configuration key, e.g. --set dynamic.detector_interval=1 (repeatable)");
  cmd->add_option(
         "--viewer", args->viewer_port,
         "Live 3-D view while it runs: serve it on http://127.0.0.1:PORT/ (default 8765; 0 = any free port)")
      ->expected(0, 1)
      ->default_str("8765");
  cmd->add_option("--keyframe-policy", args->keyframe_policy, "heuristic|adaptive")
      ->check(CLI::IsMember({"heuristic", "adaptive"}));
  cmd->callback([args] {
    const int code = run(*args);
    if (code != 0) throw CLI::RuntimeError(code);
  });
}

}  // namespace sp::app
