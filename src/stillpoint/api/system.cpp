// The public API (include/stillpoint/stillpoint.hpp) over pipeline::SlamSystem: this file only
// converts images, poses and errors at the boundary. The CLI's `run` drives this same class
// (runner.cpp, through system_access.hpp for what the API does not expose).
#include <dlfcn.h>

#include <mutex>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <utility>

#include "stillpoint/api/system_impl.hpp"
#include "stillpoint/common/data_dir.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/common/logging.hpp"
#include "stillpoint/io/camera_config.hpp"
#include "stillpoint/io/trajectory_io.hpp"
#include "stillpoint/loop/loop_detector.hpp"
#include "stillpoint/pipeline/slam_system.hpp"
#include "stillpoint/pipeline/system_config.hpp"
#include "stillpoint/version.hpp"

namespace stillpoint {

namespace fs = std::filesystem;

namespace {

// Runs `f`, turning the implementation's errors into stillpoint::Error (sp::Error's type is hidden in
// the library; the message, and an input error's file and line, are kept).
template <typename F>
auto guarded(F&& f) -> decltype(f()) {
  try {
    return f();
  } catch (const Error&) {
    throw;
  } catch (const sp::InputError& e) {
    throw Error(e.what(), e.file(), e.line());
  } catch (const sp::Error& e) {
    throw Error(e.what());
  }
}

Eigen::Isometry3d to_isometry(const sp::geo::SE3& T) {
  Eigen::Isometry3d out = Eigen::Isometry3d::Identity();
  out.linear() = T.rotation();
  out.translation() = T.translation();
  return out;
}

Eigen::Isometry3d to_isometry(const sp::io::StampedPose& p) {
  Eigen::Isometry3d out = Eigen::Isometry3d::Identity();
  out.linear() = p.q.normalized().toRotationMatrix();
  out.translation() = p.t;
  return out;
}

sp::io::CameraConfig to_internal(const Camera& c) {
  sp::io::CameraConfig out;
  auto& K = out.intrinsics;
  K.width = c.width;
  K.height = c.height;
  K.fx = c.fx;
  K.fy = c.fy;
  K.cx = c.cx;
  K.cy = c.cy;
  K.k1 = c.k1;
  K.k2 = c.k2;
  K.p1 = c.p1;
  K.p2 = c.p2;
  K.k3 = c.k3;
  out.depth_factor = c.depth_factor;
  out.fps = c.fps;
  out.depth_min = c.depth_min;
  out.depth_max = c.depth_max;
  if (c.width <= 0 || c.height <= 0 || !(c.fx > 0) || !(c.fy > 0) || !(c.depth_factor > 0) || !(c.fps > 0) ||
      !(c.depth_max > c.depth_min)) {
    throw Error(
        "stillpoint::Camera: width, height, fx, fy, depth_factor and fps must be positive and "
        "depth_max above depth_min");
  }
  return out;
}

Camera from_internal(const sp::io::CameraConfig& c) {
  Camera out;
  const auto& K = c.intrinsics;
  out.width = K.width;
  out.height = K.height;
  out.fx = K.fx;
  out.fy = K.fy;
  out.cx = K.cx;
  out.cy = K.cy;
  out.k1 = K.k1;
  out.k2 = K.k2;
  out.p1 = K.p1;
  out.p2 = K.p2;
  out.k3 = K.k3;
  out.depth_factor = c.depth_factor;
  out.fps = c.fps;
  out.depth_min = c.depth_min;
  out.depth_max = c.depth_max;
  return out;
}

// This library's own file (libstillpoint.so), the anchor for share/stillpoint.
fs::path library_file() {
  Dl_info info{};
  if (dladdr(reinterpret_cast<const void*>(&library_file), &info) != 0 && info.dli_fname != nullptr)
    return fs::path(info.dli_fname);
  return sp::current_executable();
}

}  // namespace

const char* version() { return STILLPOINT_VERSION; }

fs::path data_dir() {
  return guarded([] { return sp::resolve_data_dir(library_file()); });
}

bool has_netvlad() { return sp::pipeline::has_place_recognition(); }

const char* to_string(TrackingState state) {
  switch (state) {
    case TrackingState::NotInitialized:
      return "not_initialized";
    case TrackingState::Ok:
      return "ok";
    case TrackingState::Lost:
      return "lost";
  }
  return "?";
}

Camera Camera::load(const fs::path& file) {
  return guarded([&] { return from_internal(sp::io::load_camera_config(file)); });
}

TrackResult System::Impl::track(const sp::io::FrameData& frame) {
  sp::pipeline::FrameReport report = guarded([&] { return system->process(frame); });
  ++frames;
  TrackResult out;
  out.state = report.state == sp::track::TrackingState::Ok     ? TrackingState::Ok
              : report.state == sp::track::TrackingState::Lost ? TrackingState::Lost
                                                               : TrackingState::NotInitialized;
  out.has_pose = report.T_wc.has_value();
  if (report.T_wc) out.T_world_camera = to_isometry(*report.T_wc);
  out.features = report.features;
  out.culled_features = report.culled;
  out.keyframe = report.keyframe;
  out.culled_points = std::move(report.culled_points);
  if (report.keyframe && on_keyframe)
    on_keyframe({report.keyframe_id.value(), frame.stamp, out.T_world_camera});
  report_loops();
  return out;
}

void System::Impl::report_loops() {
  const auto closures = system->loop_closures();
  for (; loops_reported < closures.size(); ++loops_reported) {
    if (!on_loop) continue;
    const auto& c = closures[loops_reported];
    on_loop({c.query_stamp, c.match_stamp, to_isometry(c.T_query_match), c.inliers});
  }
}

System::System(const Config& config) : impl_(std::make_unique<Impl>()) {
  guarded([&] {
    sp::setup_logging(config.log_level);
    const fs::path data = data_dir();
    const fs::path config_file =
        config.config_file.empty() ? data / "config" / "stillpoint.yaml" : config.config_file;
    sp::pipeline::SystemConfig system_config =
        sp::pipeline::SystemConfig::load(config_file, config.overrides);
    if (!config.dynamic.empty()) system_config.dynamic.mode = config.dynamic;
    if (!config.loop_detector.empty()) system_config.loop.detector = config.loop_detector;
    if (!config.keyframe_policy.empty()) system_config.tracker.keyframes.policy = config.keyframe_policy;
    if (system_config.dynamic.mode == "oracle")
      throw Error("dynamic mode 'oracle' needs a sequence's boxes.txt: it is for the CLI's run only");
    if (sp::loop::needs_place_model(system_config.loop.detector) && !sp::pipeline::has_place_recognition())
      throw Error(sp::pipeline::netvlad_unavailable_message(system_config.loop.detector));
    impl_->camera = config.camera_file.empty() ? to_internal(config.camera)
                                               : sp::io::load_camera_config(config.camera_file);
    sp::pipeline::SystemOptions options;
    options.deterministic = config.deterministic;
    options.project_root = data;
    impl_->system = std::make_unique<sp::pipeline::SlamSystem>(system_config, impl_->camera, options);
    return 0;
  });
}

System::System(const fs::path& config_file, const fs::path& camera_file)
    : System([&] {
        Config c;
        c.config_file = config_file;
        c.camera_file = camera_file;
        return c;
      }()) {}

System::System(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

System::~System() {
  if (!impl_) return;
  try {
    shutdown();
  } catch (...) {  // a destructor must not throw; shutdown() reports through the log
  }
}

System::System(System&&) noexcept = default;
System& System::operator=(System&&) noexcept = default;

TrackResult System::track(const cv::Mat& color, const cv::Mat& depth, double timestamp) {
  if (!impl_) throw Error("stillpoint::System::track: moved-from system");
  if (impl_->shut_down) throw Error("stillpoint::System::track: called after shutdown()");
  const auto& cam = impl_->camera;
  const auto& K = cam.intrinsics;
  if (color.empty() || depth.empty()) throw Error("stillpoint::System::track: empty image");
  if (color.cols != K.width || color.rows != K.height || depth.cols != K.width || depth.rows != K.height) {
    throw Error("stillpoint::System::track: images are " + std::to_string(color.cols) + "x" +
                std::to_string(color.rows) + " (colour) and " + std::to_string(depth.cols) + "x" +
                std::to_string(depth.rows) + " (depth), the camera is " + std::to_string(K.width) + "x" +
                std::to_string(K.height));
  }
  if (impl_->last_stamp && !(timestamp > *impl_->last_stamp)) {
    throw Error("stillpoint::System::track: timestamps must increase (" + std::to_string(timestamp) +
                " after " + std::to_string(*impl_->last_stamp) + ")");
  }
  sp::io::FrameData frame;
  frame.index = impl_->index++;
  frame.stamp = timestamp;
  frame.depth_stamp = timestamp;
  // The frame goes on to the detector thread and the keyframe records: it owns copies of the pixels,
  // so the caller may overwrite its buffers (a video grabber's, a numpy array's) after the call.
  if (color.type() == CV_8UC3) {
    frame.bgr = color.clone();
  } else if (color.type() == CV_8UC1) {
    cv::cvtColor(color, frame.bgr, cv::COLOR_GRAY2BGR);
  } else if (color.type() == CV_8UC4) {
    cv::cvtColor(color, frame.bgr, cv::COLOR_BGRA2BGR);
  } else {
    throw Error("stillpoint::System::track: colour image must be 8-bit BGR, BGRA or grey");
  }
  if (depth.type() == CV_16UC1) {
    depth.convertTo(frame.depth, CV_32F, 1.0 / cam.depth_factor);
  } else if (depth.type() == CV_32FC1) {
    frame.depth = depth.clone();
    cv::patchNaNs(frame.depth, 0.0);  // NaN = no reading
  } else {
    throw Error("stillpoint::System::track: depth image must be 16-bit raw or 32-bit float metres");
  }
  // The same range rule as the sequence reader (io/tum_sequence.cpp).
  frame.depth.setTo(0.0f, (frame.depth < cam.depth_min) | (frame.depth > cam.depth_max));
  impl_->last_stamp = timestamp;

  TrackResult out = impl_->track(frame);
  if (impl_->system->failed()) throw Error("a StillPoint pipeline stage failed: " + impl_->system->failure());
  return out;
}

void System::on_keyframe(std::function<void(const KeyframeEvent&)> callback) {
  impl_->on_keyframe = std::move(callback);
}

void System::on_loop_closure(std::function<void(const LoopClosureEvent&)> callback) {
  impl_->on_loop = std::move(callback);
}

std::vector<StampedPose> System::trajectory() {
  std::vector<StampedPose> out;
  for (const auto& p : impl_->system->trajectory()) out.push_back({p.stamp, to_isometry(p)});
  return out;
}

std::vector<StampedPose> System::keyframe_trajectory() {
  std::vector<StampedPose> out;
  for (const auto& p : impl_->system->keyframe_trajectory()) out.push_back({p.stamp, to_isometry(p)});
  return out;
}

void System::save_trajectory(const fs::path& file, TrajectoryFormat format) {
  guarded([&] {
    const auto poses = impl_->system->trajectory();
    if (format == TrajectoryFormat::Tum) {
      sp::io::write_tum_trajectory(file, poses);
    } else {
      sp::io::write_kitti_trajectory(file, poses);
      sp::io::write_stamps(file.parent_path() / (file.stem().string() + "_times.txt"), poses);
    }
    return 0;
  });
}

void System::save_keyframe_trajectory(const fs::path& file) {
  guarded([&] {
    sp::io::write_tum_trajectory(file, impl_->system->keyframe_trajectory());
    return 0;
  });
}

std::vector<Eigen::Vector3f> System::map_points(std::size_t max_points) {
  return impl_->system->map_point_positions(max_points);
}

void System::load_map(const fs::path& file) {
  guarded([&] {
    impl_->system->load_map(file);
    return 0;
  });
}

void System::save_map(const fs::path& file) {
  shutdown();
  guarded([&] { return impl_->system->save_map(file); });
}

void System::shutdown() {
  if (!impl_ || impl_->shut_down) return;
  impl_->shut_down = true;
  impl_->system->finish();
  impl_->report_loops();
}

std::string System::statistics_json() { return impl_->system->statistics().dump(2); }

std::size_t System::frames() const { return impl_ ? impl_->frames : 0; }

}  // namespace stillpoint
