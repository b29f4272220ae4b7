// libFuzzer target: TUM trajectory files. A trajectory that reads must write and read back with the
// same number of poses and unit quaternions.
#include <cmath>
#include <cstdlib>

#include "fuzz_util.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/io/trajectory_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const auto file = sp::fuzz::scratch_file("traj.txt");
  static const auto again = sp::fuzz::scratch_file("traj_out.txt");
  sp::fuzz::write_file(file, data, size);
  std::vector<sp::io::StampedPose> poses;
  try {
    poses = sp::io::read_tum_trajectory(file);
  } catch (const sp::Error&) {
    return 0;
  }
  for (const auto& p : poses) {
    if (std::abs(p.q.norm() - 1.0) > 1e-9 || !p.t.allFinite() || !std::isfinite(p.stamp)) std::abort();
  }
  sp::io::write_tum_trajectory(again, poses);
  try {
    const auto back = sp::io::read_tum_trajectory(again);
    if (back.size() != poses.size()) std::abort();
  } catch (const sp::Error&) {
    // Stamps closer than the 1 µs the writer keeps (%.6f) collapse on reading back: documented.
  }
  return 0;
}
