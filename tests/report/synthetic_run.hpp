#pragma once
// A small fake `stillpoint run` output folder for the report tests: a circle of poses, ground truth
// offset from it by a known rigid motion plus small noise, a map cloud, one thumbnail.
#include <filesystem>
#include <string>

namespace sp::test {

struct SyntheticRunOptions {
  bool groundtruth = true;
  bool map_points = true;
  bool thumbnails = true;
  std::size_t poses = 120;
};

// Writes the folder (wiping it first) and returns it.
std::filesystem::path make_synthetic_run(const std::string& name, const SyntheticRunOptions& options = {});

// Writes `text` to `file`, creating folders.
void write_file(const std::filesystem::path& file, const std::string& text);
std::string read_file(const std::filesystem::path& file);

}  // namespace sp::test
