#include "stillpoint/eval/missing_frames.hpp"

#include <cmath>

#include "stillpoint/common/error.hpp"
#include "stillpoint/io/tum_text.hpp"

namespace sp::eval {

FilledTrajectory fill_missing_frames(const std::vector<double>& frame_stamps,
                                     const std::vector<io::StampedPose>& est, MissingFrames mode,
                                     const std::vector<std::uint32_t>& est_maps, double tolerance_s) {
  if (!est_maps.empty() && est_maps.size() != est.size()) {
    throw Error("fill_missing_frames: " + std::to_string(est_maps.size()) + " map ids for " +
                std::to_string(est.size()) + " poses");
  }
  FilledTrajectory out;
  out.poses.reserve(est.size() + frame_stamps.size());
  std::size_t next = 0;  // first estimate not yet written
  for (const double stamp : frame_stamps) {
    // Estimates up to this frame (and the one at it) go out as they are.
    bool estimated = false;
    while (next < est.size() && est[next].stamp <= stamp + tolerance_s) {
      estimated = estimated || std::abs(est[next].stamp - stamp) <= tolerance_s;
      out.poses.push_back(est[next++]);
    }
    if (estimated || mode == MissingFrames::Skip) continue;
    if (next == 0) {
      ++out.before_first;
      continue;
    }
    const io::StampedPose& before = est[next - 1];
    io::StampedPose filled = before;
    filled.stamp = stamp;
    const bool same_map = est_maps.empty() || (next < est.size() && est_maps[next - 1] == est_maps[next]);
    if (mode == MissingFrames::Interpolate && next < est.size() && same_map) {
      const io::StampedPose& after = est[next];
      const double a = (stamp - before.stamp) / (after.stamp - before.stamp);
      filled.t = (1.0 - a) * before.t + a * after.t;
      filled.q = before.q.slerp(a, after.q).normalized();
      ++out.interpolated;
    } else {
      ++out.held;
    }
    out.poses.push_back(filled);
  }
  while (next < est.size()) out.poses.push_back(est[next++]);
  return out;
}

std::vector<double> read_frame_stamps(const std::filesystem::path& frame_list) {
  std::vector<double> stamps;
  for (const auto& f : io::read_tum_file_list(frame_list)) stamps.push_back(f.stamp);
  return stamps;
}

nlohmann::json to_json(const FilledTrajectory& filled, std::size_t frames) {
  return {{"frames", frames},
          {"interpolated", filled.interpolated},
          {"held", filled.held},
          {"before_first_pose", filled.before_first}};
}

}  // namespace sp::eval
