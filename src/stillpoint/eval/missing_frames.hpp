#pragma once
// A pose for every frame: an estimate that skips the frames its system lost (ours, ORB-SLAM2's) and one
// that writes a pose for each (NGD-SLAM's) are compared on the same frames only when the skipped ones
// are filled by one rule for all.
#include <cstdint>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <vector>

#include "stillpoint/io/trajectory_io.hpp"

namespace sp::eval {

enum class MissingFrames {
  Skip,         // leave them out (the estimate as written)
  Hold,         // the last pose before the frame, as a live system would report it
  Interpolate,  // between the poses before and after the gap (by time), else held
};

struct FilledTrajectory {
  std::vector<io::StampedPose> poses;  // every estimated pose and every filled frame, in time order
  std::size_t held = 0;                // frames filled with the pose before them
  std::size_t interpolated = 0;        // frames filled between the poses around them
  std::size_t before_first = 0;        // frames before the first estimate: nothing to fill them from
};

// frame_stamps: every frame the system was given (rgb.txt), increasing. est: increasing stamps.
// est_maps: empty, or the map of each estimated pose (trajectory_maps.txt); a gap between poses in
// different maps is held, never interpolated (their frames differ). A frame counts as estimated when an
// estimate lies within tolerance_s of it. Throws sp::Error when est_maps has the wrong size.
FilledTrajectory fill_missing_frames(const std::vector<double>& frame_stamps,
                                     const std::vector<io::StampedPose>& est, MissingFrames mode,
                                     const std::vector<std::uint32_t>& est_maps = {},
                                     double tolerance_s = 0.005);

// The stamps of a sequence's frame list (rgb.txt), in order; errors name the file and line.
std::vector<double> read_frame_stamps(const std::filesystem::path& frame_list);

// {"frames", "interpolated", "held", "before_first_pose"}: stats.json's `every_frame` counts.
nlohmann::json to_json(const FilledTrajectory& filled, std::size_t frames);

}  // namespace sp::eval
