#include <gtest/gtest.h>

#include <cmath>

#include "stillpoint/eval/stats.hpp"

namespace sp::eval {
namespace {

TEST(Stats, EvenCountByHand) {
  const auto s = compute_stats({4.0, 1.0, 3.0, 2.0});
  EXPECT_EQ(s.count, 4u);
  EXPECT_DOUBLE_EQ(s.mean, 2.5);
  EXPECT_DOUBLE_EQ(s.median, 2.5);  // mean of the two middle values, like numpy
  EXPECT_DOUBLE_EQ(s.rmse, std::sqrt(30.0 / 4.0));
  EXPECT_DOUBLE_EQ(s.std, std::sqrt(1.25));  // population std: mean of (v - 2.5)^2 = 1.25
  EXPECT_DOUBLE_EQ(s.min, 1.0);
  EXPECT_DOUBLE_EQ(s.max, 4.0);
}

TEST(Stats, OddCountAndSingleValue) {
  EXPECT_DOUBLE_EQ(compute_stats({5.0, 1.0, 2.0}).median, 2.0);
  const auto one = compute_stats({0.3});
  EXPECT_DOUBLE_EQ(one.rmse, 0.3);
  EXPECT_DOUBLE_EQ(one.std, 0.0);
  EXPECT_DOUBLE_EQ(one.median, 0.3);
}

TEST(Stats, EmptyIsAllZero) {
  const auto s = compute_stats({});
  EXPECT_EQ(s.count, 0u);
  EXPECT_EQ(s.rmse, 0.0);
  EXPECT_EQ(s.max, 0.0);
}

}  // namespace
}  // namespace sp::eval
