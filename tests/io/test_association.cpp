#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <random>
#include <tuple>

#include "../support/shared_data.hpp"
#include "stillpoint/io/association.hpp"
#include "stillpoint/io/tum_text.hpp"

namespace sp::io {
namespace {

using Pairs = std::vector<std::pair<std::size_t, std::size_t>>;

TEST(Associate, MatchesWithinWindowOnly) {
  EXPECT_EQ(associate({0.0, 1.0, 2.0}, {0.005, 1.01, 2.5}, 0.0, 0.02), (Pairs{{0, 0}, {1, 1}}));
}

TEST(Associate, GreedyTakesTheSmallestDifferenceFirst) {
  // 0.01 is closer to 0.008 than 0.0 is, so it wins the only b stamp.
  EXPECT_EQ(associate({0.0, 0.01}, {0.008}, 0.0, 0.02), (Pairs{{1, 0}}));
  // One-to-one: the loser does not fall back to a farther, already used stamp.
  EXPECT_EQ(associate({0.0, 0.01, 0.05}, {0.008, 0.03}, 0.0, 0.025), (Pairs{{1, 0}, {2, 1}}));
}

TEST(Associate, TiesGoToTheEarlierStamp) {
  // Differences are exactly 0.25 (representable), as the (diff, a, b) tuple sort of associate.py.
  EXPECT_EQ(associate({1.0, 1.5}, {1.25}, 0.0, 0.5), (Pairs{{0, 0}}));
  EXPECT_EQ(associate({1.25}, {1.0, 1.5}, 0.0, 0.5), (Pairs{{0, 0}}));
}

TEST(Associate, WindowIsStrict) { EXPECT_TRUE(associate({1.0}, {1.5}, 0.0, 0.5).empty()); }

TEST(Associate, OffsetIsAddedToSecondList) {
  EXPECT_TRUE(associate({10.0, 10.5}, {0.0, 0.5}, 0.0, 0.02).empty());
  EXPECT_EQ(associate({10.0, 10.5}, {0.0, 0.5}, 10.0, 0.02), (Pairs{{0, 0}, {1, 1}}));
  EXPECT_EQ(associate({0.0, 0.5}, {10.0, 10.5}, -10.0, 0.02), (Pairs{{0, 0}, {1, 1}}));
}

TEST(Associate, GapsLeaveStampsUnmatchedAndResultIsSortedByFirstIndex) {
  EXPECT_EQ(associate({0.0, 1.0, 2.0, 3.0}, {3.001, 0.0, 2.01}, 0.0, 0.02), (Pairs{{0, 1}, {2, 2}, {3, 0}}));
}

// associate.py verbatim in spirit: all pairs, sort (diff, a, b), greedy.
Pairs brute_force(const std::vector<double>& a, const std::vector<double>& b, double offset, double md) {
  std::vector<std::tuple<double, double, double, std::size_t, std::size_t>> c;
  for (std::size_t i = 0; i < a.size(); ++i) {
    for (std::size_t j = 0; j < b.size(); ++j) {
      const double d = std::abs(a[i] - (b[j] + offset));
      if (d < md) c.emplace_back(d, a[i], b[j], i, j);
    }
  }
  std::sort(c.begin(), c.end());
  std::vector<bool> ua(a.size()), ub(b.size());
  Pairs out;
  for (const auto& [d, sa, sb, i, j] : c) {
    if (ua[i] || ub[j]) continue;
    ua[i] = ub[j] = true;
    out.emplace_back(i, j);
  }
  std::sort(out.begin(), out.end());
  return out;
}

TEST(Associate, AgreesWithBruteForceOnJitteredStreams) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> jitter(-0.012, 0.012);
  std::bernoulli_distribution drop(0.1);
  for (int trial = 0; trial < 20; ++trial) {
    std::vector<double> a, b;
    for (int k = 0; k < 200; ++k) {
      if (!drop(rng)) a.push_back(1000.0 + k / 30.0 + jitter(rng));
      if (!drop(rng)) b.push_back(1000.0 + k / 30.0 + 0.004 + jitter(rng));
    }
    std::shuffle(b.begin(), b.end(), rng);  // order must not matter
    EXPECT_EQ(associate(a, b, -0.004, 0.02), brute_force(a, b, -0.004, 0.02)) << "trial " << trial;
  }
}

TEST(Associate, ReproducesTheShippedAssociationsOfADynsynthSequence) {
  SP_REQUIRE_SHARED(SP_SHARED_DIR "/data/dynsynth/office_a_static_xyz_150/associations.txt");
  const std::filesystem::path dir = SP_SHARED_DIR "/data/dynsynth/office_a_static_xyz_150";
  const auto rgb = read_tum_file_list(dir / "rgb.txt");
  const auto depth = read_tum_file_list(dir / "depth.txt");
  std::vector<double> rs, ds;
  for (const auto& r : rgb) rs.push_back(r.stamp);
  for (const auto& d : depth) ds.push_back(d.stamp);
  const auto matches = associate(rs, ds, 0.0, 0.02);
  const auto expected = read_tum_text(dir / "associations.txt", 4);
  // The shipped list covers the first 150 frames of the render.
  ASSERT_GE(matches.size(), expected.size());
  for (std::size_t k = 0; k < expected.size(); ++k) {
    EXPECT_EQ(rgb[matches[k].first].path, expected[k].columns[1]);
    EXPECT_EQ(depth[matches[k].second].path, expected[k].columns[3]);
  }
}

}  // namespace
}  // namespace sp::io
