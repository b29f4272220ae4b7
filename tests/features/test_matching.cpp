#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <climits>
#include <random>
#include <set>

#include "stillpoint/common/error.hpp"
#include "stillpoint/features/descriptor.hpp"
#include "stillpoint/features/feature_grid.hpp"
#include "stillpoint/features/matching.hpp"
#include "stillpoint/features/orb_extractor.hpp"
#include "stillpoint/features/orb_pattern.hpp"

namespace sp::feat {
namespace {

int hamming_reference(const std::uint8_t* a, const std::uint8_t* b) {
  int d = 0;
  for (int byte = 0; byte < 32; ++byte) {
    for (int bit = 0; bit < 8; ++bit) d += ((a[byte] >> bit) & 1) != ((b[byte] >> bit) & 1) ? 1 : 0;
  }
  return d;
}

cv::Mat random_descriptors(int n, std::mt19937& rng) {
  cv::Mat d(n, 32, CV_8UC1);
  std::uniform_int_distribution<int> byte(0, 255);
  for (int r = 0; r < n; ++r) {
    for (int c = 0; c < 32; ++c) d.at<std::uint8_t>(r, c) = static_cast<std::uint8_t>(byte(rng));
  }
  return d;
}

TEST(Hamming, MatchesBitByBitReference) {
  std::mt19937 rng(7);
  const cv::Mat d = random_descriptors(64, rng);
  for (int i = 0; i < d.rows; ++i) {
    for (int j = 0; j < d.rows; ++j) {
      const int ref = hamming_reference(d.ptr<std::uint8_t>(i), d.ptr<std::uint8_t>(j));
      ASSERT_EQ(hamming_distance(d.ptr<std::uint8_t>(i), d.ptr<std::uint8_t>(j)), ref);
      ASSERT_EQ(hamming_distance(d.row(i), d.row(j)), ref);
    }
  }
  // Hand-worked: all zeros vs all ones = 256; one flipped bit = 1; a pointer into an odd offset works.
  std::uint8_t zeros[33] = {}, ones[33];
  std::fill(std::begin(ones), std::end(ones), 0xFF);
  EXPECT_EQ(hamming_distance(zeros, ones), 256);
  zeros[32] = 0;
  std::uint8_t one_bit[33] = {};
  one_bit[1 + 17] = 0x10;
  EXPECT_EQ(hamming_distance(zeros + 1, one_bit + 1), 1);
  EXPECT_THROW(hamming_distance(d.row(0).colRange(0, 16), d.row(1).colRange(0, 16)), sp::Error);
}

TEST(OrbPatternTest, FixedDeterministicAndInsideDisc) {
  const OrbPattern a = OrbPattern::generate(), b = OrbPattern::generate();
  EXPECT_EQ(a.x, b.x);
  EXPECT_EQ(a.y, b.y);
  EXPECT_NE(OrbPattern::generate(1).fingerprint(), a.fingerprint());
  int sum_sq = 0;
  for (int i = 0; i < 2 * OrbPattern::kPairs; ++i) {
    const int x = a.x[static_cast<std::size_t>(i)], y = a.y[static_cast<std::size_t>(i)];
    ASSERT_LE(x * x + y * y, 15 * 15);
    sum_sq += x * x + y * y;
  }
  for (int i = 0; i < OrbPattern::kPairs; ++i) {
    const auto k = static_cast<std::size_t>(2 * i);
    ASSERT_FALSE(a.x[k] == a.x[k + 1] && a.y[k] == a.y[k + 1]) << "pair " << i;
  }
  // Gaussian with sigma 6.2 per axis, truncated to the disc: mean squared radius well above 0.
  const double mean_sq = sum_sq / (2.0 * OrbPattern::kPairs);
  EXPECT_GT(mean_sq, 40.0);
  EXPECT_LT(mean_sq, 80.0);
  // Pinned: a change of the pattern invalidates every vocabulary trained on our descriptors.
  EXPECT_EQ(a.fingerprint(), 0x50b9a505cb71719aULL) << std::hex << a.fingerprint();
}

TEST(OrbPatternTest, StandardIsASelectionOfGeneratedCandidates) {
  const OrbPattern st = OrbPattern::decorrelated();
  std::set<std::array<int, 4>> candidates;
  for (std::uint64_t k = 0; k < 64; ++k) {
    const OrbPattern g = OrbPattern::generate(OrbPattern::kDefaultSeed + k);
    for (std::size_t i = 0; i < OrbPattern::kPairs; ++i) {
      candidates.insert({g.x[2 * i], g.y[2 * i], g.x[2 * i + 1], g.y[2 * i + 1]});
    }
  }
  std::set<std::array<int, 4>> seen;
  for (std::size_t i = 0; i < OrbPattern::kPairs; ++i) {
    const std::array<int, 4> t{st.x[2 * i], st.y[2 * i], st.x[2 * i + 1], st.y[2 * i + 1]};
    EXPECT_TRUE(candidates.count(t)) << "pair " << i;
    EXPECT_TRUE(seen.insert(t).second) << "duplicate pair " << i;
    EXPECT_LE(t[0] * t[0] + t[1] * t[1], 225);
    EXPECT_LE(t[2] * t[2] + t[3] * t[3], 225);
  }
  // Pinned like generate(): the extractor's default descriptors depend on this table.
  EXPECT_EQ(st.fingerprint(), 0xdd9b5ef30dffc890ULL) << std::hex << st.fingerprint();
  // The default stays generate(): the shipped vocabulary was trained on its descriptors.
  EXPECT_EQ(OrbExtractor(OrbConfig{}).pattern().fingerprint(), OrbPattern::generate().fingerprint());
  OrbConfig c;
  c.pattern = "decorrelated";
  EXPECT_EQ(OrbExtractor(c).pattern().fingerprint(), st.fingerprint());
}

TEST(MatchRatio, AgreesWithBruteForce) {
  std::mt19937 rng(3);
  const cv::Mat train = random_descriptors(200, rng);
  // Queries: noisy copies of some train rows (few flipped bits) plus unrelated rows.
  cv::Mat query(80, 32, CV_8UC1);
  std::uniform_int_distribution<int> pick(0, 199), bitpos(0, 255);
  std::vector<int> source(80, -1);
  for (int q = 0; q < 80; ++q) {
    if (q % 2 == 0) {
      source[static_cast<std::size_t>(q)] = pick(rng);
      train.row(source[static_cast<std::size_t>(q)]).copyTo(query.row(q));
      for (int k = 0; k < 20; ++k) {
        const int b = bitpos(rng);
        query.at<std::uint8_t>(q, b / 8) ^= static_cast<std::uint8_t>(1 << (b % 8));
      }
    } else {
      random_descriptors(1, rng).copyTo(query.row(q));
    }
  }
  const auto matches = match_ratio(query, train, 0.8f, 64, false);
  std::size_t k = 0;
  for (int q = 0; q < query.rows; ++q) {
    std::vector<std::pair<int, int>> d;
    for (int t = 0; t < train.rows; ++t) d.push_back({hamming_reference(query.ptr(q), train.ptr(t)), t});
    std::sort(d.begin(), d.end());
    const bool accept = d[0].first <= 64 && d[0].first < 0.8f * static_cast<float>(d[1].first);
    if (source[static_cast<std::size_t>(q)] >= 0) {
      EXPECT_TRUE(accept) << q;  // 20 bits of noise against ~128 for unrelated rows
    }
    if (!accept) continue;
    ASSERT_LT(k, matches.size());
    EXPECT_EQ(matches[k].query, q);
    EXPECT_EQ(matches[k].train, d[0].second);
    EXPECT_EQ(matches[k].distance, d[0].first);
    ++k;
  }
  EXPECT_EQ(k, matches.size());
  EXPECT_EQ(k, 40u);
  EXPECT_TRUE(match_ratio(query, cv::Mat(), 0.8f).empty());
}

TEST(MatchRatio, CrossCheckDropsSharedTrainRows) {
  // Two queries whose nearest train row is the same: only the closer one survives the cross check.
  cv::Mat train = cv::Mat::zeros(2, 32, CV_8UC1);
  train.row(1).setTo(0xFF);
  cv::Mat query = cv::Mat::zeros(2, 32, CV_8UC1);
  query.at<std::uint8_t>(0, 0) = 0x01;  // distance 1 to train 0
  query.at<std::uint8_t>(1, 0) = 0x03;  // distance 2 to train 0
  EXPECT_EQ(match_ratio(query, train, 0.8f, 64, false).size(), 2u);
  const auto cc = match_ratio(query, train, 0.8f, 64, true);
  ASSERT_EQ(cc.size(), 1u);
  EXPECT_EQ(cc[0].query, 0);
  EXPECT_EQ(cc[0].train, 0);
  EXPECT_EQ(cc[0].distance, 1);
  // max_distance gate.
  EXPECT_TRUE(match_ratio(query, train, 0.8f, 0, false).empty());
}

TEST(RotationHistogramTest, KeepsThreeDominantBins) {
  RotationHistogram h(30);  // 12-degree bins centred on multiples of 12
  std::size_t id = 0;
  for (int i = 0; i < 20; ++i) h.add(i % 2 == 0 ? 3.f : -4.f, id++);  // ids 0..19 -> bin 0 (wraps)
  for (int i = 0; i < 5; ++i) h.add(121.f, id++);                     // 20..24 -> bin 10 (25 %)
  for (int i = 0; i < 3; ++i) h.add(-60.f, id++);                     // 25..27 -> bin 25 (15 %)
  h.add(200.f, id++);                                                 // 28 -> bin 17 (5 %)
  h.add(725.f, id++);                                                 // 29 -> bin 0
  EXPECT_EQ(h.outliers(), (std::vector<std::size_t>{28}));
  EXPECT_EQ(h.inliers().size(), 29u);

  // Second and third bins below 10 % of the first are dropped too.
  RotationHistogram g(30);
  for (std::size_t i = 0; i < 40; ++i) g.add(90.f, i);
  for (std::size_t i = 40; i < 43; ++i) g.add(180.f, i);  // 7.5 %
  g.add(270.f, 43);
  EXPECT_EQ(g.outliers(), (std::vector<std::size_t>{40, 41, 42, 43}));

  // 2nd kept at >= 10 %, 3rd below it dropped.
  RotationHistogram f(30);
  for (std::size_t i = 0; i < 30; ++i) f.add(0.f, i);
  for (std::size_t i = 30; i < 33; ++i) f.add(48.f, i);  // 10 %
  f.add(96.f, 33);
  f.add(96.f, 34);  // 6.7 %
  EXPECT_EQ(f.outliers(), (std::vector<std::size_t>{33, 34}));
  EXPECT_TRUE(RotationHistogram(30).outliers().empty());
  EXPECT_THROW(RotationHistogram(2), sp::Error);
}

TEST(FeatureGridTest, AgreesWithBruteForce) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> ux(-20.f, 660.f), uy(-20.f, 500.f);  // some outside the image
  std::uniform_int_distribution<int> level(0, 7);
  std::vector<cv::Point2f> pts(1500);
  std::vector<int> oct(pts.size());
  for (std::size_t i = 0; i < pts.size(); ++i) {
    pts[i] = {ux(rng), uy(rng)};
    oct[i] = level(rng);
  }
  const FeatureGrid grid(pts, oct, cv::Size(640, 480));
  EXPECT_EQ(grid.size(), pts.size());
  std::uniform_real_distribution<float> ur(0.5f, 80.f);
  std::vector<std::size_t> reused;
  for (int q = 0; q < 300; ++q) {
    const float x = ux(rng), y = uy(rng), r = ur(rng);
    const int lo = q % 3 == 0 ? -1 : level(rng);
    const int hi = q % 4 == 0 ? -1 : std::max(lo, level(rng));
    std::vector<std::size_t> expected;
    for (std::size_t i = 0; i < pts.size(); ++i) {
      if (lo >= 0 && oct[i] < lo) continue;
      if (hi >= 0 && oct[i] > hi) continue;
      if (std::abs(pts[i].x - x) < r && std::abs(pts[i].y - y) < r) expected.push_back(i);
    }
    ASSERT_EQ(grid.in_area(x, y, r, lo, hi), expected) << "query " << q;
    grid.in_area(x, y, r, reused, lo, hi);
    ASSERT_EQ(reused, expected);
  }
  EXPECT_TRUE(FeatureGrid().in_area(1.f, 1.f, 5.f).empty());
  EXPECT_THROW(FeatureGrid(pts, std::vector<int>(3), cv::Size(640, 480)), sp::Error);
}

}  // namespace
}  // namespace sp::feat

namespace sp::feat {
namespace {

TEST(DistinctiveDescriptor, MinimisesMedianDistance) {
  std::mt19937 rng(21);
  for (int trial = 0; trial < 20; ++trial) {
    const int n = 1 + trial % 7;
    const cv::Mat d = random_descriptors(n, rng);
    std::vector<const std::uint8_t*> ptrs;
    for (int i = 0; i < n; ++i) ptrs.push_back(d.ptr<std::uint8_t>(i));
    int best = -1, best_median = 1000;
    for (int i = 0; i < n; ++i) {
      std::vector<int> dist;
      for (int j = 0; j < n; ++j)
        dist.push_back(
            hamming_reference(ptrs[static_cast<std::size_t>(i)], ptrs[static_cast<std::size_t>(j)]));
      std::sort(dist.begin(), dist.end());
      const int median = dist[static_cast<std::size_t>((n - 1) / 2)];
      if (median < best_median) best_median = median, best = i;
    }
    EXPECT_EQ(distinctive_descriptor_index(ptrs), best) << "trial " << trial;
  }
  // Hand-worked: two near-identical descriptors and an outlier: one of the pair wins.
  cv::Mat d = cv::Mat::zeros(3, 32, CV_8UC1);
  d.at<std::uint8_t>(1, 0) = 1;
  d.row(2).setTo(0xFF);
  EXPECT_EQ(distinctive_descriptor_index({d.ptr(2), d.ptr(0), d.ptr(1)}), 1);
  EXPECT_EQ(distinctive_descriptor_index({}), -1);
}

TEST(BestInArea, AgreesWithBruteForce) {
  std::mt19937 rng(4);
  std::uniform_real_distribution<float> ux(0.f, 640.f), uy(0.f, 480.f);
  std::uniform_int_distribution<int> level(0, 7);
  const int n = 600;
  std::vector<cv::Point2f> pts(n);
  std::vector<int> oct(n);
  for (int i = 0; i < n; ++i)
    pts[static_cast<std::size_t>(i)] = {ux(rng), uy(rng)}, oct[static_cast<std::size_t>(i)] = level(rng);
  const cv::Mat desc = random_descriptors(n, rng);
  const cv::Mat queries = random_descriptors(100, rng);
  const FeatureGrid grid(pts, oct, cv::Size(640, 480));
  std::vector<std::size_t> scratch;
  for (int q = 0; q < queries.rows; ++q) {
    const float x = ux(rng), y = uy(rng), r = 60.f;
    const int lo = q % 2 == 0 ? -1 : 2, hi = q % 3 == 0 ? -1 : 5;
    const auto skip = [](std::size_t i) { return i % 5 == 0; };
    const AreaMatch m =
        best_in_area(grid, desc, queries.ptr<std::uint8_t>(q), x, y, r, lo, hi, scratch, skip);
    int best = AreaMatch::kNone, second = AreaMatch::kNone, best_i = -1;
    for (int i = 0; i < n; ++i) {
      const auto u = static_cast<std::size_t>(i);
      if (skip(u) || (lo >= 0 && oct[u] < lo) || (hi >= 0 && oct[u] > hi)) continue;
      if (std::abs(pts[u].x - x) >= r || std::abs(pts[u].y - y) >= r) continue;
      const int d = hamming_reference(queries.ptr(q), desc.ptr(i));
      if (d < best) {
        second = best, best = d, best_i = i;
      } else if (d < second) {
        second = d;
      }
    }
    ASSERT_EQ(m.index, best_i) << q;
    EXPECT_EQ(m.distance, best);
    EXPECT_EQ(m.second_distance, second);
    if (best_i >= 0) {
      EXPECT_EQ(m.level, oct[static_cast<std::size_t>(best_i)]);
    }
  }
}

}  // namespace
}  // namespace sp::feat
