#include <gtest/gtest.h>

#include <random>

#include "stillpoint/common/error.hpp"
#include "stillpoint/io/trajectory_io.hpp"
#include "test_util.hpp"

namespace sp::io {
namespace {

TEST(TrajectoryIo, WriteReadRoundTrip) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-50.0, 50.0);
  std::vector<StampedPose> poses;
  for (int k = 0; k < 100; ++k) {
    StampedPose p;
    p.stamp = 1341846056.0 + k / 30.0;
    p.t = Eigen::Vector3d(u(rng), u(rng), u(rng) * 1e-3);
    // Not normalised on purpose: the writer must store a unit quaternion.
    p.q = Eigen::Quaterniond(Eigen::Vector4d::Random().normalized() * 1.3);
    poses.push_back(p);
  }
  const auto file = test::scratch_dir() / "sub" / "traj.txt";
  write_tum_trajectory(file, poses);
  EXPECT_FALSE(std::filesystem::exists(file.string() + ".tmp"));
  const auto back = read_tum_trajectory(file);
  ASSERT_EQ(back.size(), poses.size());
  for (std::size_t k = 0; k < poses.size(); ++k) {
    EXPECT_NEAR(back[k].stamp, poses[k].stamp, 1e-6);
    EXPECT_LT((back[k].t - poses[k].t).norm(), 1e-8);  // 10 significant digits of values below 50
    EXPECT_NEAR(back[k].q.norm(), 1.0, 1e-12);
    // Same rotation (q and -q are equal rotations).
    EXPECT_NEAR(std::abs(back[k].q.dot(poses[k].q.normalized())), 1.0, 1e-9);
  }
}

TEST(TrajectoryIo, OverwritesAnExistingFile) {
  const auto file = test::write_text(test::scratch_dir() / "traj.txt", "garbage that is not a trajectory\n");
  write_tum_trajectory(file, {StampedPose{1.0, Eigen::Vector3d(1, 2, 3), Eigen::Quaterniond::Identity()}});
  const auto back = read_tum_trajectory(file);
  ASSERT_EQ(back.size(), 1u);
  EXPECT_EQ(back[0].t, Eigen::Vector3d(1, 2, 3));
}

int error_line(const std::string& text) {
  const auto file = test::write_text(test::scratch_dir() / "bad.txt", text);
  try {
    (void)read_tum_trajectory(file);
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), file.string());
    return e.line();
  }
  ADD_FAILURE() << "no InputError for:\n" << text;
  return -1;
}

TEST(TrajectoryIo, MalformedLinesNameTheLine) {
  const std::string ok = "# timestamp tx ty tz qx qy qz qw\n1.0 0 0 0 0 0 0 1\n";
  EXPECT_EQ(error_line(ok + "2.0 0 0 0 0 0 1\n"), 3);       // 7 columns
  EXPECT_EQ(error_line(ok + "2.0 0 0 zero 0 0 0 1\n"), 3);  // non-numeric
  EXPECT_EQ(error_line(ok + "2.0 0 0 0 0 0 0 1.01\n"), 3);  // |q| = 1.01
  EXPECT_EQ(error_line(ok + "\n0.5 0 0 0 0 0 0 1\n"), 4);   // out of order
  EXPECT_EQ(error_line(ok + "2.0 0 0 0 0 0 0 1 9\n"), 3);   // 9 columns
}

TEST(TrajectoryIo, SlightlyOffUnitQuaternionIsAcceptedAndNormalised) {
  const auto file = test::write_text(test::scratch_dir() / "t.txt", "1.0 1 2 3 0 0 0 1.0005\n");
  const auto p = read_tum_trajectory(file);
  ASSERT_EQ(p.size(), 1u);
  EXPECT_NEAR(p[0].q.norm(), 1.0, 1e-12);
  EXPECT_EQ(p[0].t, Eigen::Vector3d(1, 2, 3));
}

TEST(TrajectoryIo, FileOrderIsXyzw) {
  const auto file = test::write_text(test::scratch_dir() / "t.txt", "1.0 0 0 0 0.6 0 0 0.8\n");
  const auto p = read_tum_trajectory(file);
  EXPECT_DOUBLE_EQ(p[0].q.x(), 0.6);
  EXPECT_DOUBLE_EQ(p[0].q.w(), 0.8);
}

}  // namespace
}  // namespace sp::io
