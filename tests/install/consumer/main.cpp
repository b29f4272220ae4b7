// Tracks a TUM-layout sequence through the public API only (#include <stillpoint/stillpoint.hpp>):
// reads associations.txt and the images itself, feeds every frame to track(), then checks what the API
// promises. Exit 0 = every check passed; each failure prints what failed.
//   consumer SEQUENCE_DIR [MIN_TRACKED_SHARE]
#include <cmath>
#include <cstdio>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <stillpoint/stillpoint.hpp>
#include <string>

namespace {
int failures = 0;
void check(bool ok, const std::string& what) {
  if (!ok) {
    std::fprintf(stderr, "FAILED: %s\n", what.c_str());
    ++failures;
  }
}
}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: consumer SEQUENCE_DIR [MIN_TRACKED_SHARE]\n");
    return 2;
  }
  const std::filesystem::path seq = argv[1];
  const double min_share = argc > 2 ? std::stod(argv[2]) : 0.9;
  std::printf("StillPoint %s, data %s\n", stillpoint::version(), stillpoint::data_dir().c_str());

  stillpoint::Config config;  // the shipped defaults (YOLOX-nano + flow, adaptive keyframes, bow-sequence)
  config.camera = stillpoint::Camera::load(seq / "camera.yaml");
  config.deterministic = true;
  stillpoint::System slam(config);
  std::size_t keyframe_events = 0;
  slam.on_keyframe([&](const stillpoint::KeyframeEvent& e) {
    ++keyframe_events;
    check(e.T_world_camera.linear().isUnitary(1e-6), "keyframe pose has a rotation");
  });

  std::ifstream list(seq / "associations.txt");
  check(static_cast<bool>(list), "associations.txt readable");
  std::string line;
  std::size_t frames = 0, with_pose = 0, culled = 0, keyframes = 0;
  while (std::getline(list, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream in(line);
    double t_rgb = 0, t_depth = 0;
    std::string rgb, depth;
    in >> t_rgb >> rgb >> t_depth >> depth;
    const cv::Mat color = cv::imread((seq / rgb).string(), cv::IMREAD_COLOR);
    const cv::Mat raw = cv::imread((seq / depth).string(), cv::IMREAD_UNCHANGED);
    const stillpoint::TrackResult r = slam.track(color, raw, t_rgb);
    ++frames;
    check(r.has_pose == (r.state == stillpoint::TrackingState::Ok), "has_pose exactly when Ok");
    if (r.has_pose) {
      ++with_pose;
      check(r.T_world_camera.linear().isUnitary(1e-6) && r.T_world_camera.translation().allFinite(),
            "tracked pose is a rigid transform");
      check(r.T_world_camera.translation().norm() < 5.0, "tracked pose within 5 m of the start (demo: ~1 m)");
    }
    culled += r.culled_features;
    check(r.culled_points.size() == r.culled_features, "a culled point per culled feature");
    for (const cv::Point2f& p : r.culled_points)
      check(p.x >= 0 && p.y >= 0 && p.x < color.cols && p.y < color.rows, "culled points inside the image");
    keyframes += r.keyframe ? 1 : 0;
  }
  slam.shutdown();
  const auto trajectory = slam.trajectory();
  std::printf("frames %zu, with pose %zu, trajectory %zu, keyframes %zu (events %zu), culled %zu\n", frames,
              with_pose, trajectory.size(), keyframes, keyframe_events, culled);
  check(frames > 0, "some frames read");
  // One pose per tracked frame: the trajectory and the per-frame results agree.
  check(trajectory.size() == with_pose, "trajectory() has one pose per frame tracked");
  check(static_cast<double>(with_pose) >= min_share * static_cast<double>(frames),
        "at least the given share of frames tracked");
  check(keyframe_events == keyframes && keyframes >= 2, "a keyframe event per keyframe, at least two");
  // The demo has people walking through it: the default detector + flow culling drops some features.
  check(culled > 0, "some features culled as dynamic");
  for (std::size_t i = 1; i < trajectory.size(); ++i)
    check(trajectory[i].timestamp > trajectory[i - 1].timestamp, "trajectory timestamps increase");
  // The map's points, subsampled on request; the trajectory files, one line per pose.
  const auto points = slam.map_points();
  check(points.size() > 100, "the map has points");
  check(slam.map_points(50).size() == 50, "map_points(50) gives 50 points");
  const std::filesystem::path out = "consumer_out";  // in the working directory
  std::filesystem::create_directories(out);
  slam.save_trajectory(out / "tum.txt");
  slam.save_trajectory(out / "kitti.txt", stillpoint::TrajectoryFormat::Kitti);
  const auto count_lines = [](const std::filesystem::path& file, std::size_t words) {
    std::ifstream in(file);
    std::size_t n = 0;
    for (std::string l; std::getline(in, l);) {
      if (l.empty() || l[0] == '#') continue;
      std::istringstream w(l);
      std::size_t k = 0;
      for (std::string x; w >> x;) ++k;
      n += k == words ? 1 : 0;
    }
    return n;
  };
  check(count_lines(out / "tum.txt", 8) == trajectory.size(), "TUM file: 8 numbers per pose");
  check(count_lines(out / "kitti.txt", 12) == trajectory.size(), "KITTI file: 12 numbers per pose");
  check(count_lines(out / "kitti_times.txt", 1) == trajectory.size(), "KITTI times file: a stamp per pose");
  bool refused = false;
  try {
    (void)slam.track(cv::Mat(), cv::Mat(), 1e12);
  } catch (const stillpoint::Error&) {
    refused = true;
  }
  check(refused, "track() after shutdown() throws stillpoint::Error");
  std::printf("%s\n", failures == 0 ? "consumer: all checks passed" : "consumer: FAILED");
  return failures == 0 ? 0 : 1;
}
