#pragma once
// Map files: a versioned, checksummed binary snapshot of the map's live keyframes and map points, so a
// later run can relocalise in it and go on (`stillpoint run --save-map F` / `--load-map F`).
//
// Layout (every number little-endian, fixed width; docs/map_files.md has the full field table):
//   magic "SPMAPBIN" (8 bytes), u32 format version (kMapFormatVersion)
//   sections, each: u32 tag (ASCII), u64 payload length, payload, u32 CRC32(tag, length, payload)
//     "HEAD" counts, next ids, camera, ORB pyramid, vocabulary reference
//     "KFRM" keyframes: pose, stamp, keypoints, depth, descriptors, point ids, graph edges, JPEG thumbnail
//     "MPNT" map points: position, descriptor, normal, distances, observations, reference, counters
//     "END " u64 file size, u32 CRC32 of every byte before this section
// Only live (non-bad) records are written; references to records that are not written are dropped
// or redirected at save time, so a loader can reject every dangling id as corruption.
// Files are written to "<file>.tmp" and renamed, so a crash never leaves a half-written map behind.
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include "stillpoint/geometry/camera.hpp"
#include "stillpoint/map/byte_codec.hpp"  // crc32
#include "stillpoint/map/map.hpp"

namespace sp::map {

inline constexpr std::uint32_t kMapFormatVersion = 2;  // 2: keyframes carry their map id

// What a map file records besides the records: enough to refuse a map built for another camera or
// pyramid, and to tell the user when the vocabulary differs from the one the map was built with.
struct MapFileInfo {
  geo::CameraIntrinsics camera;
  int pyramid_levels = 8;
  double pyramid_scale_factor = 1.2;
  std::string vocabulary_name;            // file name only (empty: no vocabulary was loaded)
  std::uint64_t vocabulary_words = 0;     // words in that vocabulary
  std::uint64_t vocabulary_checksum = 0;  // the .spv file's own FNV-1a-64 trailer (vocabulary_fingerprint)
  bool operator==(const MapFileInfo&) const;
};

// The stored FNV-1a-64 checksum of a .spv vocabulary file (its last 8 bytes; the vocabulary loader
// verifies it, so it identifies the content). Throws sp::InputError when the file cannot be read.
std::uint64_t vocabulary_fingerprint(const std::filesystem::path& vocabulary_file);

struct MapContents {
  MapFileInfo info;
  std::vector<Keyframe> keyframes;  // sorted by id; `children` and the feature grid rebuilt
  std::vector<MapPoint> points;     // sorted by id
  KeyframeId next_keyframe_id{1};
  PointId next_point_id{1};
};

struct MapSaveResult {
  std::size_t keyframes = 0;
  std::size_t points = 0;
  std::uint64_t bytes = 0;
};

// Snapshot of the live records under one view (the map lock is held only while copying).
MapContents snapshot_map(Map& map, const MapFileInfo& info);
// Serialises and writes atomically (temp file + rename). Throws sp::Error when it cannot write.
std::vector<std::uint8_t> serialize_map(const MapContents& contents);
MapSaveResult save_map(Map& map, const std::filesystem::path& file, const MapFileInfo& info);

// Parses and validates a whole file image. `name` is used in error messages (the file path).
// Every problem is an sp::InputError naming the file: "not a StillPoint map file" (magic), both
// versions (version mismatch), the byte offset and section (truncation), the section (CRC mismatch),
// the record and the missing id (dangling references).
MapContents parse_map(std::span<const std::uint8_t> bytes, const std::string& name);
MapContents read_map_file(const std::filesystem::path& file);
// Reads `file` into `map`, which must be empty (sp::Error otherwise); returns the header.
MapFileInfo load_map(const std::filesystem::path& file, Map& map);

// Recomputes every section CRC and the overall CRC of a map file image in place, as far as its
// section framing can be walked. For tests and the fuzz harness, which forge well-sealed files to
// reach the structural checks behind the checksums.
void reseal_map_bytes(std::vector<std::uint8_t>& bytes);

}  // namespace sp::map
