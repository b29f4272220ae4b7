#pragma once
// Reads the point clouds `stillpoint run` writes (map_points.ply, dense_cloud.ply) and other simple
// PLY files: one `vertex` element with float/double x y z and optional uchar red green blue; other
// scalar properties are skipped. binary_little_endian and ascii are supported.
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace sp::report {

struct PointCloud {
  std::vector<float> xyz;         // 3 per point
  std::vector<std::uint8_t> rgb;  // 3 per point, empty when the file has no colour
  [[nodiscard]] std::size_t size() const { return xyz.size() / 3; }
};

// Throws sp::InputError naming the file (and the header line) for anything it cannot read.
PointCloud read_ply(const std::filesystem::path& file);

}  // namespace sp::report
