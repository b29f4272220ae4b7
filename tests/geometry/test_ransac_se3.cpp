#include <gtest/gtest.h>

#include <random>

#include "stillpoint/common/error.hpp"
#include "stillpoint/geometry/ransac_se3.hpp"

namespace {
using sp::geo::SE3;

struct Data {
  std::vector<Eigen::Vector3d> src, dst;
  std::vector<bool> outlier;
  SE3 T;
};

Data make_data(int n, double outlier_ratio, double noise, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-2.0, 2.0), u01(0.0, 1.0);
  std::normal_distribution<double> g(0.0, noise);
  Data d;
  sp::geo::Vec6 xi;
  xi << 0.5, -1.0, 0.3, 0.2, -0.7, 1.1;
  d.T = SE3::exp(xi);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d p(u(rng), u(rng), u(rng) + 4.0);
    Eigen::Vector3d q = d.T * p + Eigen::Vector3d(g(rng), g(rng), g(rng));
    const bool out = u01(rng) < outlier_ratio;
    if (out) q += Eigen::Vector3d(u(rng), u(rng), u(rng)).normalized() * (0.3 + u01(rng));
    d.src.push_back(p);
    d.dst.push_back(q);
    d.outlier.push_back(out);
  }
  return d;
}

TEST(RansacSe3, RecoversTransformWithOutliers) {
  const Data d = make_data(200, 0.4, 0.005, 3);
  const auto res = sp::geo::estimate_se3_ransac(d.src, d.dst, {});
  ASSERT_TRUE(res.has_value());
  EXPECT_LT((res->T_dst_src.translation() - d.T.translation()).norm(), 0.005);
  EXPECT_LT(sp::geo::rotation_angle(res->T_dst_src.rotation() * d.T.rotation().transpose()), 0.005);
  int wrong = 0;
  for (std::size_t i = 0; i < d.src.size(); ++i) wrong += res->inliers[i] == d.outlier[i] ? 1 : 0;
  EXPECT_EQ(wrong, 0);
  int count = 0;
  for (bool b : res->inliers) count += b ? 1 : 0;
  EXPECT_EQ(count, res->inlier_count);
}

TEST(RansacSe3, DeterministicForSeed) {
  const Data d = make_data(100, 0.3, 0.01, 4);
  sp::geo::RansacSe3Config c;
  c.iterations = 20;
  const auto a = sp::geo::estimate_se3_ransac(d.src, d.dst, c);
  const auto b = sp::geo::estimate_se3_ransac(d.src, d.dst, c);
  ASSERT_TRUE(a && b);
  EXPECT_EQ(a->T_dst_src.matrix(), b->T_dst_src.matrix());
  EXPECT_EQ(a->inliers, b->inliers);
}

TEST(RansacSe3, RejectsPureNoiseAndBadInput) {
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(-3.0, 3.0);
  std::vector<Eigen::Vector3d> src, dst;
  for (int i = 0; i < 60; ++i) {
    src.emplace_back(u(rng), u(rng), u(rng));
    dst.emplace_back(u(rng), u(rng), u(rng));
  }
  EXPECT_FALSE(sp::geo::estimate_se3_ransac(src, dst, {}).has_value());
  EXPECT_FALSE(sp::geo::estimate_se3_ransac({src[0], src[1]}, {dst[0], dst[1]}, {}).has_value());
  dst.pop_back();
  EXPECT_THROW(sp::geo::estimate_se3_ransac(src, dst, {}), sp::Error);
}

}  // namespace
