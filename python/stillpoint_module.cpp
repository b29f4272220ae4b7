// Python bindings of the public API (include/stillpoint/stillpoint.hpp): numpy images in, 4x4 numpy
// poses out. Only the public API is used: this module is a consumer of libstillpoint like any other.
#include <pybind11/eigen.h>
#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <cstdint>
#include <stillpoint/stillpoint.hpp>
#include <string>

namespace py = pybind11;
using stillpoint::Camera;
using stillpoint::Config;
using stillpoint::System;
using stillpoint::TrackResult;

namespace {

// A cv::Mat header over a C-contiguous numpy array (no copy; track() copies what it keeps).
cv::Mat as_mat(const py::array& a, int depth, const char* what) {
  if (a.ndim() != 2 && a.ndim() != 3)
    throw py::value_error(std::string(what) + " must be an H x W or H x W x C array");
  const int channels = a.ndim() == 3 ? static_cast<int>(a.shape(2)) : 1;
  if (channels < 1 || channels > 4)
    throw py::value_error(std::string(what) + " has " + std::to_string(channels) + " channels");
  return cv::Mat(static_cast<int>(a.shape(0)), static_cast<int>(a.shape(1)), CV_MAKETYPE(depth, channels),
                 const_cast<void*>(a.data()));
}

Eigen::Matrix4d matrix(const Eigen::Isometry3d& T) { return T.matrix(); }

// Poses as (timestamps: N, poses: N x 4 x 4).
py::tuple stack(const std::vector<stillpoint::StampedPose>& poses) {
  py::array_t<double> stamps(static_cast<py::ssize_t>(poses.size()));
  py::array_t<double> mats({static_cast<py::ssize_t>(poses.size()), py::ssize_t{4}, py::ssize_t{4}});
  auto s = stamps.mutable_unchecked<1>();
  auto m = mats.mutable_unchecked<3>();
  for (std::size_t i = 0; i < poses.size(); ++i) {
    const auto k = static_cast<py::ssize_t>(i);
    s(k) = poses[i].timestamp;
    const Eigen::Matrix4d T = poses[i].T_world_camera.matrix();
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) m(k, r, c) = T(r, c);
  }
  return py::make_tuple(stamps, mats);
}

TrackResult track(System& system, const py::array& color_in, const py::array& depth_in, double timestamp,
                  const std::string& color_order) {
  using uint8_array = py::array_t<std::uint8_t, py::array::c_style>;
  if (!py::isinstance<py::array_t<std::uint8_t>>(color_in))
    throw py::type_error("color must be a uint8 array (H x W x 3 BGR/RGB, or H x W grey)");
  const auto color = uint8_array::ensure(color_in);
  cv::Mat color_mat = as_mat(color, CV_8U, "color");
  cv::Mat bgr;
  if (color_order == "rgb" && color_mat.channels() >= 3) {
    bgr.create(color_mat.size(), CV_8UC3);
    const int from_to[] = {0, 2, 1, 1, 2, 0};
    cv::mixChannels(&color_mat, 1, &bgr, 1, from_to, 3);
    color_mat = bgr;
  } else if (color_order != "bgr" && color_order != "rgb") {
    throw py::value_error("color_order must be 'bgr' or 'rgb'");
  }
  py::array depth;
  cv::Mat depth_mat;
  if (py::isinstance<py::array_t<std::uint16_t>>(depth_in)) {
    depth = py::array_t<std::uint16_t, py::array::c_style>::ensure(depth_in);
    depth_mat = as_mat(depth, CV_16U, "depth");
  } else if (py::isinstance<py::array_t<float>>(depth_in) || py::isinstance<py::array_t<double>>(depth_in)) {
    depth = py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(depth_in);
    depth_mat = as_mat(depth, CV_32F, "depth");
  } else {
    throw py::type_error("depth must be uint16 (raw, / camera.depth_factor = metres) or float metres");
  }
  py::gil_scoped_release release;  // callbacks take the GIL back (see on_keyframe)
  return system.track(color_mat, depth_mat, timestamp);
}

}  // namespace

PYBIND11_MODULE(stillpoint, m) {
  m.doc() = "StillPoint: RGB-D visual SLAM that keeps only the still points (docs/library.md)";
  py::register_exception<stillpoint::Error>(m, "Error", PyExc_RuntimeError);
  m.attr("__version__") = stillpoint::version();
  m.def("version", &stillpoint::version);
  m.def("data_dir", &stillpoint::data_dir, "config/, data/, models/ of this installation");
  m.def("has_netvlad", &stillpoint::has_netvlad, "whether the 'netvlad' loop detector is built");

  py::class_<Camera>(m, "Camera", "Pinhole RGB-D camera with OpenCV radial-tangential distortion")
      .def(py::init<>())
      .def_readwrite("width", &Camera::width)
      .def_readwrite("height", &Camera::height)
      .def_readwrite("fx", &Camera::fx)
      .def_readwrite("fy", &Camera::fy)
      .def_readwrite("cx", &Camera::cx)
      .def_readwrite("cy", &Camera::cy)
      .def_readwrite("k1", &Camera::k1)
      .def_readwrite("k2", &Camera::k2)
      .def_readwrite("p1", &Camera::p1)
      .def_readwrite("p2", &Camera::p2)
      .def_readwrite("k3", &Camera::k3)
      .def_readwrite("depth_factor", &Camera::depth_factor)
      .def_readwrite("fps", &Camera::fps)
      .def_readwrite("depth_min", &Camera::depth_min)
      .def_readwrite("depth_max", &Camera::depth_max)
      .def_static("load", &Camera::load, py::arg("file"),
                  "Reads StillPoint camera.yaml, ORB-SLAM2/3 or stella_vslam settings");

  py::class_<Config>(m, "Config", "What to run; empty strings keep the configuration file's values")
      .def(py::init<>())
      .def_readwrite("config_file", &Config::config_file)
      .def_readwrite("overrides", &Config::overrides)
      .def_readwrite("camera", &Config::camera)
      .def_readwrite("camera_file", &Config::camera_file)
      .def_readwrite("dynamic", &Config::dynamic)
      .def_readwrite("loop_detector", &Config::loop_detector)
      .def_readwrite("keyframe_policy", &Config::keyframe_policy)
      .def_readwrite("deterministic", &Config::deterministic)
      .def_readwrite("log_level", &Config::log_level);

  py::class_<TrackResult>(m, "TrackResult")
      .def_property_readonly("state", [](const TrackResult& r) { return stillpoint::to_string(r.state); })
      .def_readonly("has_pose", &TrackResult::has_pose)
      .def_property_readonly("T_world_camera",
                             [](const TrackResult& r) -> py::object {
                               if (!r.has_pose) return py::none();
                               return py::cast(matrix(r.T_world_camera));
                             })
      .def_readonly("features", &TrackResult::features)
      .def_readonly("culled_features", &TrackResult::culled_features)
      .def_readonly("keyframe", &TrackResult::keyframe)
      .def_property_readonly(
          "culled_points",
          [](const TrackResult& r) {
            py::array_t<float> out({static_cast<py::ssize_t>(r.culled_points.size()), py::ssize_t{2}});
            auto o = out.mutable_unchecked<2>();
            for (std::size_t i = 0; i < r.culled_points.size(); ++i) {
              o(static_cast<py::ssize_t>(i), 0) = r.culled_points[i].x;
              o(static_cast<py::ssize_t>(i), 1) = r.culled_points[i].y;
            }
            return out;
          })
      .def("__repr__", [](const TrackResult& r) {
        return std::string("TrackResult(state=") + stillpoint::to_string(r.state) +
               ", culled_features=" + std::to_string(r.culled_features) + ")";
      });

  py::class_<System>(m, "System")
      .def(py::init([](const Config& c) {
             py::gil_scoped_release release;
             return std::make_unique<System>(c);
           }),
           py::arg("config") = Config())
      .def("track", &track, py::arg("color"), py::arg("depth"), py::arg("timestamp"),
           py::arg("color_order") = "bgr",
           "One frame: color uint8 HxWx3 (BGR as cv2.imread gives, or color_order='rgb') or HxW grey; "
           "depth uint16 raw or float metres. Returns a TrackResult (T_world_camera: 4x4 or None).")
      .def(
          "on_keyframe",
          [](System& s, py::function f) {
            s.on_keyframe([f](const stillpoint::KeyframeEvent& e) {
              py::gil_scoped_acquire gil;
              f(e.id, e.timestamp, matrix(e.T_world_camera));
            });
          },
          py::arg("callback"), "callback(id, timestamp, T_world_camera 4x4), called inside track()")
      .def(
          "on_loop_closure",
          [](System& s, py::function f) {
            s.on_loop_closure([f](const stillpoint::LoopClosureEvent& e) {
              py::gil_scoped_acquire gil;
              f(e.query_timestamp, e.match_timestamp, matrix(e.T_query_match), e.inliers);
            });
          },
          py::arg("callback"), "callback(query_timestamp, match_timestamp, T_query_match 4x4, inliers)")
      .def(
          "trajectory", [](System& s) { return stack(s.trajectory()); },
          "(timestamps N, poses N x 4 x 4) of every tracked frame, map corrections applied")
      .def("keyframe_trajectory", [](System& s) { return stack(s.keyframe_trajectory()); })
      .def(
          "save_trajectory",
          [](System& s, const std::filesystem::path& file, const std::string& format) {
            if (format != "tum" && format != "kitti")
              throw py::value_error("format must be 'tum' or 'kitti'");
            s.save_trajectory(file, format == "tum" ? stillpoint::TrajectoryFormat::Tum
                                                    : stillpoint::TrajectoryFormat::Kitti);
          },
          py::arg("file"), py::arg("format") = "tum",
          "Writes trajectory(): 'tum', or 'kitti' (plus <stem>_times.txt beside it)")
      .def("save_keyframe_trajectory", &System::save_keyframe_trajectory, py::arg("file"))
      .def(
          "map_points",
          [](System& s, std::size_t max_points) {
            const auto points = s.map_points(max_points);
            py::array_t<float> out({static_cast<py::ssize_t>(points.size()), py::ssize_t{3}});
            auto o = out.mutable_unchecked<2>();
            for (std::size_t i = 0; i < points.size(); ++i)
              for (int c = 0; c < 3; ++c) o(static_cast<py::ssize_t>(i), c) = points[i][c];
            return out;
          },
          py::arg("max_points") = 0, "map point positions, N x 3 float32 (at most max_points; 0 = all)")
      .def("load_map", &System::load_map, py::arg("file"), py::call_guard<py::gil_scoped_release>())
      .def("save_map", &System::save_map, py::arg("file"), py::call_guard<py::gil_scoped_release>())
      .def("shutdown", &System::shutdown, py::call_guard<py::gil_scoped_release>())
      .def("statistics",
           [](System& s) { return py::module_::import("json").attr("loads")(s.statistics_json()); })
      .def_property_readonly("frames", &System::frames);
}
