#include "stillpoint/report/run_data.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <sstream>

#include "stillpoint/common/error.hpp"

namespace sp::report {

namespace {

std::string read_file(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw InputError(file.string(), 0, "cannot open");
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// Keeps every k-th point so the page stays a few MB; the subsample is spread over the whole map.
void subsample(PointCloud& cloud, std::size_t max_points) {
  const std::size_t n = cloud.size();
  if (n <= max_points || max_points == 0) return;
  PointCloud out;
  out.xyz.reserve(max_points * 3);
  for (std::size_t k = 0; k < max_points; ++k) {
    const std::size_t i = k * n / max_points;
    out.xyz.insert(out.xyz.end(), cloud.xyz.begin() + static_cast<std::ptrdiff_t>(3 * i),
                   cloud.xyz.begin() + static_cast<std::ptrdiff_t>(3 * i + 3));
    if (!cloud.rgb.empty())
      out.rgb.insert(out.rgb.end(), cloud.rgb.begin() + static_cast<std::ptrdiff_t>(3 * i),
                     cloud.rgb.begin() + static_cast<std::ptrdiff_t>(3 * i + 3));
  }
  cloud = std::move(out);
}

std::optional<PointCloud> load_cloud(const std::filesystem::path& file, std::size_t max_points,
                                     std::size_t& total, std::vector<std::string>& notes) {
  if (!std::filesystem::exists(file)) return std::nullopt;
  try {
    PointCloud cloud = read_ply(file);
    total = cloud.size();
    subsample(cloud, max_points);
    return cloud;
  } catch (const Error& e) {
    notes.push_back(fmt::format("{} not shown: {}", file.filename().string(), e.what()));
    spdlog::warn("{}", e.what());
    return std::nullopt;
  }
}

void load_thumbnails(const std::filesystem::path& dir, RunData& run) {
  if (!std::filesystem::is_directory(dir)) return;
  const auto index_file = dir / "index.json";
  std::vector<Thumbnail> listed;
  if (std::filesystem::exists(index_file)) {
    try {
      const auto j = nlohmann::json::parse(read_file(index_file));
      for (const auto& f : j.at("frames")) {
        Thumbnail t;
        t.index = f.at("index").get<std::size_t>();
        t.stamp = f.value("stamp", 0.0);
        t.features = f.value("features", std::size_t{0});
        t.culled = f.value("culled", std::size_t{0});
        t.file = f.at("file").get<std::string>();
        if (t.file.find('/') != std::string::npos || t.file.find("..") != std::string::npos)
          throw Error("file names must be plain names: " + t.file);
        listed.push_back(std::move(t));
      }
    } catch (const std::exception& e) {
      run.notes.push_back(fmt::format("{} ignored: {}", index_file.string(), e.what()));
      listed.clear();
    }
  }
  if (listed.empty()) {  // no (usable) index: every JPEG in the folder, in name order
    std::vector<std::string> names;
    for (const auto& entry : std::filesystem::directory_iterator(dir))
      if (entry.path().extension() == ".jpg") names.push_back(entry.path().filename().string());
    std::sort(names.begin(), names.end());
    for (auto& n : names) {
      Thumbnail t;
      std::size_t index = 0;
      if (std::sscanf(n.c_str(), "frame_%zu.jpg", &index) == 1) t.index = index;
      t.file = std::move(n);
      listed.push_back(std::move(t));
    }
  }
  for (Thumbnail& t : listed) {
    const auto file = dir / t.file;
    if (!std::filesystem::exists(file)) {
      run.notes.push_back("thumbnail listed but missing: " + file.string());
      continue;
    }
    t.jpeg = read_file(file);
    run.thumbnails.push_back(std::move(t));
  }
}

}  // namespace

nlohmann::json read_stats(const std::filesystem::path& file) {
  if (!std::filesystem::exists(file))
    throw InputError(file.string(), 0, "missing: is this the output folder of `stillpoint run`?");
  const std::string text = read_file(file);
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(text);
  } catch (const nlohmann::json::parse_error& e) {
    // The parser reports a byte offset; users fix files by line.
    const std::size_t at = std::min<std::size_t>(e.byte, text.size());
    const int line =
        1 + static_cast<int>(std::count(text.begin(), text.begin() + static_cast<std::ptrdiff_t>(at), '\n'));
    throw InputError(file.string(), line, fmt::format("not valid JSON ({})", e.what()));
  }
  if (!j.is_object()) throw InputError(file.string(), 1, "expected a JSON object");
  // The numbers the page shows must have the right type when present.
  for (const char* key : {"frames", "lost_frames", "keyframes", "map_points", "fps", "wall_s"})
    if (j.contains(key) && !j[key].is_number())
      throw InputError(file.string(), 0, fmt::format("key '{}' must be a number", key));
  if (j.contains("stages_ms") && !j["stages_ms"].is_object())
    throw InputError(file.string(), 0, "key 'stages_ms' must be an object");
  return j;
}

RunData load_run(const std::filesystem::path& dir, const LoadOptions& options) {
  if (!std::filesystem::is_directory(dir)) throw Error("run folder not found: " + dir.string());
  RunData run;
  run.dir = dir;
  run.stats = read_stats(dir / "stats.json");
  const auto trajectory_file = dir / "trajectory.txt";
  if (!std::filesystem::exists(trajectory_file)) throw InputError(trajectory_file.string(), 0, "missing");
  run.trajectory = io::read_tum_trajectory(trajectory_file);  // InputError with file:line
  if (run.trajectory.empty()) run.notes.push_back("trajectory.txt holds no pose (tracking never started)");
  const auto keyframes_file = dir / "keyframes.txt";
  if (std::filesystem::exists(keyframes_file)) {
    try {
      run.keyframes = io::read_tum_trajectory(keyframes_file);
    } catch (const Error& e) {
      run.notes.push_back(std::string("keyframes not shown: ") + e.what());
    }
  }

  std::optional<std::filesystem::path> gt = options.groundtruth;
  if (gt && !std::filesystem::exists(*gt)) throw InputError(gt->string(), 0, "ground truth file not found");
  if (!gt && run.stats.contains("dataset") && run.stats["dataset"].is_string()) {
    const std::filesystem::path candidate =
        std::filesystem::path(run.stats["dataset"].get<std::string>()) / "groundtruth.txt";
    if (std::filesystem::exists(candidate)) gt = candidate;
  }
  if (gt) {
    run.groundtruth_file = gt;
    // An explicitly given file must be right; a discovered one only loses its sections.
    try {
      run.groundtruth = io::read_tum_trajectory(*gt);
    } catch (const Error& e) {
      if (options.groundtruth) throw;
      run.notes.push_back(std::string("ground truth not used: ") + e.what());
    }
    if (!run.groundtruth.empty() && run.trajectory.size() >= 3) {
      try {
        run.eval = eval::evaluate(run.groundtruth, run.trajectory, eval::EvalOptions{});
      } catch (const Error& e) {
        run.notes.push_back(std::string("no evaluation against the ground truth: ") + e.what());
      }
    }
  } else {
    run.notes.push_back(
        "no ground truth (give --groundtruth FILE, or keep groundtruth.txt in the sequence folder)");
  }

  run.map_points =
      load_cloud(dir / "map_points.ply", options.max_map_points, run.map_points_total, run.notes);
  run.dense_cloud =
      load_cloud(dir / "dense_cloud.ply", options.max_dense_points, run.dense_points_total, run.notes);
  load_thumbnails(dir / "culled", run);
  return run;
}

}  // namespace sp::report
