#pragma once
// Everything a report shows, loaded from a `stillpoint run` output folder. stats.json and
// trajectory.txt are required; ground truth, keyframes, PLY clouds and thumbnails are optional and
// their absence (or a broken optional file) becomes a note on the page, not an error.
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "stillpoint/eval/evaluate.hpp"
#include "stillpoint/io/trajectory_io.hpp"
#include "stillpoint/report/ply_reader.hpp"

namespace sp::report {

struct Thumbnail {
  std::size_t index = 0;  // frame index in the sequence
  double stamp = 0;
  std::size_t features = 0, culled = 0;  // 0/0 when the index does not say
  std::string file;                      // name inside RUN_DIR/culled
  std::string jpeg;                      // file contents
};

struct LoadOptions {
  // Ground truth in TUM format; default: groundtruth.txt in the sequence folder named by stats.json
  // "dataset", when it exists.
  std::optional<std::filesystem::path> groundtruth;
  std::size_t max_map_points = 150'000;    // the page embeds at most this many (evenly subsampled)
  std::size_t max_dense_points = 250'000;  // idem for the dense cloud
};

struct RunData {
  std::filesystem::path dir;
  nlohmann::json stats;
  std::vector<io::StampedPose> trajectory;
  std::vector<io::StampedPose> keyframes;  // empty without keyframes.txt
  std::optional<std::filesystem::path> groundtruth_file;
  std::vector<io::StampedPose> groundtruth;
  std::optional<eval::EvalResult> eval;  // with ground truth that overlaps the trajectory
  std::optional<PointCloud> map_points, dense_cloud;
  std::size_t map_points_total = 0, dense_points_total = 0;  // before subsampling
  std::vector<Thumbnail> thumbnails;
  std::vector<std::string> notes;  // why an optional section is empty
};

// Throws sp::InputError naming the file for a missing or malformed stats.json (with the line of a
// JSON syntax error) and a missing or malformed trajectory.txt (with the line).
RunData load_run(const std::filesystem::path& dir, const LoadOptions& options = {});

// Parses stats.json; exposed for tests.
nlohmann::json read_stats(const std::filesystem::path& file);

}  // namespace sp::report
