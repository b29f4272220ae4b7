#include "synthetic_run.hpp"

#include <fmt/format.h>

#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numbers>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "stillpoint/io/trajectory_io.hpp"
#include "stillpoint/pipeline/run_artifacts.hpp"

namespace sp::test {

void write_file(const std::filesystem::path& file, const std::string& text) {
  std::filesystem::create_directories(file.parent_path());
  std::ofstream out(file, std::ios::binary);
  out << text;
}

std::string read_file(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::filesystem::path make_synthetic_run(const std::string& name, const SyntheticRunOptions& options) {
  const auto root = std::filesystem::path(SP_TEST_TMP_DIR) / "report" / name;
  std::filesystem::remove_all(root);
  const auto run = root / "run";
  const auto seq = root / "sequence";
  std::filesystem::create_directories(run);
  std::filesystem::create_directories(seq);

  std::vector<io::StampedPose> est, gt;
  const Eigen::Quaterniond q_gt(Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitY()));
  const Eigen::Vector3d t_gt(1.5, -0.2, 3.0);
  for (std::size_t i = 0; i < options.poses; ++i) {
    const double a = 2 * std::numbers::pi * static_cast<double>(i) / static_cast<double>(options.poses);
    io::StampedPose p;
    p.stamp = 100.0 + 0.05 * static_cast<double>(i);
    p.t = Eigen::Vector3d(std::cos(a), 0.02 * std::sin(3 * a), std::sin(a));
    est.push_back(p);
    io::StampedPose g = p;
    // Ground truth: the same path moved rigidly, with a deterministic wobble of a few mm.
    g.t = q_gt * p.t + t_gt + Eigen::Vector3d(0.004 * std::sin(7 * a), 0, 0.003 * std::cos(5 * a));
    g.q = q_gt;
    gt.push_back(g);
  }
  io::write_tum_trajectory(run / "trajectory.txt", est);
  std::vector<io::StampedPose> kfs;
  for (std::size_t i = 0; i < est.size(); i += 10) kfs.push_back(est[i]);
  io::write_tum_trajectory(run / "keyframes.txt", kfs);
  if (options.groundtruth) io::write_tum_trajectory(seq / "groundtruth.txt", gt);

  nlohmann::json stats = {{"dataset", seq.string()},
                          {"frames", 123},
                          {"tracked_frames", 119},
                          {"lost_frames", 4},
                          {"keyframes", 17},
                          {"keyframes_created", 21},
                          {"map_points", 4567},
                          {"fps", 29.5},
                          {"wall_s", 4.2},
                          {"dynamic_mode", "detector+flow"},
                          {"culled_features_per_frame", 12.5},
                          {"completed", true}};
  stats["every_frame"] = {
      {"frames", 123}, {"interpolated", 4}, {"ate_rmse_m", 0.0123}, {"ate_max_m", 0.0456}};
  stats["stages_ms"] = {{"extract",
                         {{"count", 123},
                          {"total_ms", 400.0},
                          {"mean_ms", 3.3},
                          {"median_ms", 3.25},
                          {"p95_ms", 7.5},
                          {"max_ms", 9.0}}},
                        {"track",
                         {{"count", 123},
                          {"total_ms", 900.0},
                          {"mean_ms", 7.3},
                          {"median_ms", 6.75},
                          {"p95_ms", 14.125},
                          {"max_ms", 20.0}}}};
  write_file(run / "stats.json", stats.dump(2));

  if (options.map_points) {
    std::vector<pipeline::PlyPoint> cloud;
    for (int i = 0; i < 500; ++i) {
      const double a = 0.0126 * i;
      cloud.push_back({static_cast<float>(2 * std::cos(a)), static_cast<float>(0.5 * std::sin(5 * a)),
                       static_cast<float>(2 * std::sin(a)), static_cast<std::uint8_t>(i % 256), 128, 200});
    }
    pipeline::write_ply(run / "map_points.ply", cloud);
  }
  if (options.thumbnails) {
    cv::Mat img(90, 120, CV_8UC3, cv::Scalar(30, 60, 90));
    cv::circle(img, {60, 45}, 10, cv::Scalar(40, 40, 255), cv::FILLED);
    std::vector<uchar> jpeg;
    cv::imencode(".jpg", img, jpeg);
    write_file(run / "culled" / "frame_000010.jpg", std::string(jpeg.begin(), jpeg.end()));
    write_file(
        run / "culled" / "index.json",
        R"({"stride": 10, "frames": [{"index": 10, "stamp": 100.5, "file": "frame_000010.jpg", "features": 800, "culled": 37}]})");
  }
  return run;
}

}  // namespace sp::test
