#pragma once
// StillPoint's public API: RGB-D SLAM that keeps only the still points, embedded in your process.
//
//   #include <stillpoint/stillpoint.hpp>
//   stillpoint::System slam(stillpoint::Config{});          // the shipped defaults, camera of the demo
//   auto r = slam.track(bgr, depth, timestamp);            // one frame
//   if (r.has_pose) use(r.T_world_camera);
//   slam.shutdown();                                       // drain local mapping and loop closing
//   auto poses = slam.trajectory();                        // every tracked frame, map corrections applied
//
// Only Eigen, OpenCV (core) and the standard library appear here; the implementation (yaml-cpp, Ceres,
// spdlog, ...) stays inside libstillpoint. Link with find_package(StillPoint) -> StillPoint::stillpoint,
// or pkg-config stillpoint. docs/library.md has the whole story.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <opencv2/core.hpp>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#define STILLPOINT_API __attribute__((visibility("default")))

namespace stillpoint {

namespace internal {
class SystemAccess;  // the stillpoint CLI's access to what the API does not expose; not installed
}  // namespace internal

// Every error the API throws on purpose (bad configuration or camera file, unreadable map, images that
// do not fit the camera, calls in the wrong state). The message names the file and line when there is one.
class STILLPOINT_API Error : public std::runtime_error {
 public:
  explicit Error(const std::string& what, std::string file = {}, int line = 0)
      : std::runtime_error(what), file_(std::move(file)), line_(line) {}
  // The input file at fault (a configuration, camera, map file) and its 1-based line; empty and 0
  // when the error is not about a file's content, or the line is not known.
  [[nodiscard]] const std::string& file() const noexcept { return file_; }
  [[nodiscard]] int line() const noexcept { return line_; }

 private:
  std::string file_;
  int line_ = 0;
};

// "0.1.0".
STILLPOINT_API const char* version();

// The data folder (config/, data/, models/): $STILLPOINT_DATA_DIR, else share/stillpoint beside the
// installed library. Throws Error when there is none.
STILLPOINT_API std::filesystem::path data_dir();

// Whether this build has ParC_NetVLAD (libtorch), i.e. the 'netvlad' and 'hybrid' loop detectors.
STILLPOINT_API bool has_netvlad();

// A pinhole RGB-D camera with radial-tangential (OpenCV) distortion.
struct STILLPOINT_API Camera {
  int width = 640, height = 480;  // pixels
  double fx = 535.4, fy = 539.2, cx = 320.1, cy = 247.6;
  double k1 = 0, k2 = 0, p1 = 0, p2 = 0, k3 = 0;
  double depth_factor = 5000;  // raw 16-bit depth units per metre (TUM: 5000, most sensors: 1000)
  double fps = 30;             // nominal frame rate, Hz
  double depth_min = 0.1;      // metres; depth outside [depth_min, depth_max] is treated as missing
  double depth_max = 8.0;

  // Reads a camera file: StillPoint's camera.yaml, ORB-SLAM2/3 or stella_vslam settings.
  static Camera load(const std::filesystem::path& file);
};

// What to run. Everything not named here comes from the configuration file (every key documented in
// share/stillpoint/config/stillpoint.yaml) and can be changed with `overrides`.
struct STILLPOINT_API Config {
  std::filesystem::path config_file;   // empty: the shipped default (data_dir()/config/stillpoint.yaml)
  std::vector<std::string> overrides;  // "section.key=value", e.g. "dynamic.detector_interval=1"
  Camera camera;                       // or:
  std::filesystem::path camera_file;   // when set, the camera is read from it (any Camera::load format)
  // The paper's switches; empty keeps the file's value.
  std::string dynamic;          // off | flow | detector | detector+flow | auto
  std::string loop_detector;    // off | bow-keyframe | bow-sequence | netvlad | hybrid
  std::string keyframe_policy;  // heuristic | adaptive
  // Fixed seeds, every stage on the caller's thread: identical results twice (slower).
  bool deterministic = false;
  std::string log_level = "warn";  // trace | debug | info | warn | error | off (global to the process)
};

enum class TrackingState {
  NotInitialized,  // no map yet (the first frame with enough valid depth starts one)
  Ok,              // tracked: the frame has a pose
  Lost,            // not tracked; the system tries to relocalise in the map on each new frame
};
STILLPOINT_API const char* to_string(TrackingState state);

struct TrackResult {
  TrackingState state = TrackingState::NotInitialized;
  bool has_pose = false;  // true exactly when state == Ok
  // The camera's pose in the world (map) frame as tracked now; later map corrections (local bundle
  // adjustment, loop closure) refine it: trajectory() returns the corrected poses.
  Eigen::Isometry3d T_world_camera = Eigen::Isometry3d::Identity();
  std::size_t features = 0;                // ORB features the tracker used
  std::size_t culled_features = 0;         // features dropped as dynamic (on moving people) in this frame
  bool keyframe = false;                   // this frame became a keyframe
  std::vector<cv::Point2f> culled_points;  // image positions (pixels) of the culled features
};

struct StampedPose {
  double timestamp = 0;  // seconds, as passed to track()
  Eigen::Isometry3d T_world_camera = Eigen::Isometry3d::Identity();
};

struct KeyframeEvent {
  std::uint64_t id = 0;
  double timestamp = 0;
  Eigen::Isometry3d T_world_camera = Eigen::Isometry3d::Identity();  // at creation
};

struct LoopClosureEvent {
  double query_timestamp = 0;                                       // the keyframe that closed the loop
  double match_timestamp = 0;                                       // the earlier keyframe it recognised
  Eigen::Isometry3d T_query_match = Eigen::Isometry3d::Identity();  // verified relative pose
  int inliers = 0;
};

enum class TrajectoryFormat {
  Tum,    // "t tx ty tz qx qy qz qw" a line (TUM RGB-D, evo --tum)
  Kitti,  // KITTI odometry: T_world_camera's first three rows, 12 numbers a line; the timestamps go
          // to <stem>_times.txt beside the file (like KITTI's times.txt)
};

class STILLPOINT_API System {
 public:
  // Loads the configuration, the camera, the vocabulary and the detector, and starts local mapping and
  // loop closing on their own threads (none with deterministic). Throws Error for bad input.
  explicit System(const Config& config);
  // The same with a configuration file and a camera file (any Camera::load format).
  System(const std::filesystem::path& config_file, const std::filesystem::path& camera_file);
  ~System();  // shutdown()
  System(const System&) = delete;
  System& operator=(const System&) = delete;
  System(System&&) noexcept;
  System& operator=(System&&) noexcept;

  // One RGB-D frame. `color`: 8-bit BGR (as cv::imread gives it) or 8-bit grey, the camera's size.
  // `depth`: 16-bit raw (metres = value / Camera::depth_factor) or 32-bit float metres, same size;
  // 0 = no reading. `timestamp` in seconds, increasing. The images are copied when needed: the caller
  // may reuse its buffers after the call. Keyframe and loop-closure callbacks run inside this call.
  TrackResult track(const cv::Mat& color, const cv::Mat& depth, double timestamp);

  // Called on the thread that calls track() (and shutdown(), for loops closed while draining).
  void on_keyframe(std::function<void(const KeyframeEvent&)> callback);
  void on_loop_closure(std::function<void(const LoopClosureEvent&)> callback);

  // Every tracked frame (frames before initialisation and while lost have none), each pose resolved
  // against the current, corrected map.
  [[nodiscard]] std::vector<StampedPose> trajectory();
  [[nodiscard]] std::vector<StampedPose> keyframe_trajectory();
  // Writes trajectory() (keyframe_trajectory(): TUM) to a file at full precision. Throws Error when
  // the file cannot be written.
  void save_trajectory(const std::filesystem::path& file, TrajectoryFormat format = TrajectoryFormat::Tum);
  void save_keyframe_trajectory(const std::filesystem::path& file);
  // Positions of the map's points in the world frame, at most `max_points` of them evenly subsampled
  // (0 = all), for drawing the map.
  [[nodiscard]] std::vector<Eigen::Vector3f> map_points(std::size_t max_points = 0);

  // Before the first frame: relocalise in a saved map and extend it (docs/map_files.md).
  void load_map(const std::filesystem::path& file);
  // Saves the map; calls shutdown() first so that the map is final.
  void save_map(const std::filesystem::path& file);

  // Waits for local mapping and loop closing to finish their queues and stops them; track() is refused
  // afterwards. Idempotent.
  void shutdown();

  // Run statistics (per-stage timing, keyframes, map points, culling and loop counts) as JSON text.
  [[nodiscard]] std::string statistics_json();
  // Frames given to track() so far.
  [[nodiscard]] std::size_t frames() const;

 private:
  friend class internal::SystemAccess;
  struct Impl;
  explicit System(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace stillpoint
