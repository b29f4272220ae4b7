#pragma once
// TUM trajectory files: `timestamp tx ty tz qx qy qz qw`, the pose of the camera in the world
// (T_world_camera).
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <filesystem>
#include <vector>

namespace sp::io {

struct StampedPose {
  double stamp = 0;  // seconds
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
};

// Errors (sp::InputError, file:line) for a wrong column count, a non-numeric value, a quaternion whose
// norm is off 1 by more than 1e-3 and timestamps that do not increase. Quaternions are normalised.
std::vector<StampedPose> read_tum_trajectory(const std::filesystem::path& file);

// Writes stamps with %.6f and the rest with 10 significant digits, unit quaternions, through a temporary
// file renamed into place so a reader never sees half a file.
void write_tum_trajectory(const std::filesystem::path& file, const std::vector<StampedPose>& poses);

// KITTI odometry format: one line per pose, the first three rows of T_world_camera row-major
// (`r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz`), no timestamps (write_stamps writes them, one per
// line, like KITTI's times.txt). Same temporary-file rename as above.
void write_kitti_trajectory(const std::filesystem::path& file, const std::vector<StampedPose>& poses);
void write_stamps(const std::filesystem::path& file, const std::vector<StampedPose>& poses);

}  // namespace sp::io
