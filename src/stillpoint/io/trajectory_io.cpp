#include "stillpoint/io/trajectory_io.hpp"

#include <fmt/format.h>

#include <cmath>
#include <cstdio>
#include <fstream>

#include "stillpoint/common/error.hpp"
#include "stillpoint/io/tum_text.hpp"

namespace sp::io {

std::vector<StampedPose> read_tum_trajectory(const std::filesystem::path& file) {
  std::vector<StampedPose> out;
  for (const auto& rec : read_tum_text(file, 8)) {
    double v[8];
    for (std::size_t k = 0; k < 8; ++k) {
      if (!parse_double(rec.columns[k], v[k])) {
        throw InputError(file.string(), rec.line,
                         "column " + std::to_string(k + 1) + " '" + rec.columns[k] + "' is not a number");
      }
    }
    StampedPose p;
    p.stamp = v[0];
    p.t = Eigen::Vector3d(v[1], v[2], v[3]);
    p.q = Eigen::Quaterniond(v[7], v[4], v[5], v[6]);  // file order qx qy qz qw
    const double norm = p.q.norm();
    if (std::abs(norm - 1.0) > 1e-3) {
      throw InputError(file.string(), rec.line,
                       fmt::format("quaternion norm {:.6f} is not 1 (tolerance 1e-3)", norm));
    }
    p.q.normalize();
    out.push_back(p);
  }
  return out;
}

namespace {
// Writes through a temporary file renamed into place.
template <class Body>
void write_atomically(const std::filesystem::path& file, Body&& body) {
  if (file.has_parent_path()) std::filesystem::create_directories(file.parent_path());
  const std::filesystem::path tmp = file.string() + ".tmp";
  {
    std::ofstream out(tmp);
    if (!out) throw InputError(tmp.string(), 0, "cannot open for writing");
    body(out);
    out.flush();
    if (!out) throw InputError(tmp.string(), 0, "write failed");
  }
  std::error_code ec;
  std::filesystem::rename(tmp, file, ec);
  if (ec) {
    std::filesystem::remove(tmp, ec);
    throw InputError(file.string(), 0, "cannot move the finished file into place");
  }
}
}  // namespace

void write_tum_trajectory(const std::filesystem::path& file, const std::vector<StampedPose>& poses) {
  write_atomically(file, [&](std::ofstream& out) {
    out << "# timestamp tx ty tz qx qy qz qw\n";
    for (const auto& p : poses) {
      const Eigen::Quaterniond q = p.q.normalized();
      out << fmt::format("{:.6f} {:.10g} {:.10g} {:.10g} {:.10g} {:.10g} {:.10g} {:.10g}\n", p.stamp, p.t.x(),
                         p.t.y(), p.t.z(), q.x(), q.y(), q.z(), q.w());
    }
  });
}

void write_kitti_trajectory(const std::filesystem::path& file, const std::vector<StampedPose>& poses) {
  write_atomically(file, [&](std::ofstream& out) {
    for (const auto& p : poses) {
      const Eigen::Matrix3d R = p.q.normalized().toRotationMatrix();
      for (int r = 0; r < 3; ++r) {
        out << fmt::format("{}{:.10g} {:.10g} {:.10g} {:.10g}", r == 0 ? "" : " ", R(r, 0), R(r, 1), R(r, 2),
                           p.t(r));
      }
      out << "\n";
    }
  });
}

void write_stamps(const std::filesystem::path& file, const std::vector<StampedPose>& poses) {
  write_atomically(file, [&](std::ofstream& out) {
    for (const auto& p : poses) out << fmt::format("{:.6f}\n", p.stamp);
  });
}

}  // namespace sp::io
