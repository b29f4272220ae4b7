#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <set>

#include "stillpoint/common/config_reader.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/loop/hybrid_detector.hpp"
#include "synthetic_stream.hpp"

namespace sp::loop {
namespace {

using testing::make_stream;
using testing::revisit_path;

Eigen::VectorXf random_unit(std::mt19937& rng) {
  std::normal_distribution<float> n(0.f, 1.f);
  Eigen::VectorXf v(256);  // random directions in 256-D are nearly orthogonal: d² ≈ 2
  for (int i = 0; i < 256; ++i) v(i) = n(rng);
  return v.normalized();
}

// One appearance per place plus per-keyframe noise: the same place looks alike (d² ≈ 2 noise²).
void describe_by_place(testing::Stream& s, std::uint32_t seed, float noise) {
  std::mt19937 rng(seed);
  std::vector<Eigen::VectorXf> place;
  for (int p = 0; p < 32; ++p) place.push_back(random_unit(rng));
  for (std::size_t k = 0; k < s.keyframes.size(); ++k)
    s.keyframes[k].global =
        (place[static_cast<std::size_t>(s.place[k])] + noise * random_unit(rng)).normalized();
}

using Pair = std::pair<std::uint64_t, std::uint64_t>;
std::set<Pair> pairs(const std::vector<LoopCandidate>& cs) {
  std::set<Pair> out;
  for (const auto& c : cs) out.emplace(c.query.value(), c.match.value());
  return out;
}

LoopDetectorParams hybrid_over(const std::string& bow) {
  LoopDetectorParams p;
  p.hybrid.bow = bow;
  return p;
}

// With descriptors that agree with BoW, the hybrid passes exactly BoW's candidates (re-ordered only).
TEST(HybridLoopDetector, KeepsBowCandidatesWhoseAppearanceAgrees) {
  for (const std::string bow : {"bow-keyframe", "bow-sequence"}) {
    auto stream = make_stream(revisit_path(), 8, 11);
    describe_by_place(stream, 5, 0.3f);
    auto inner = make_loop_detector(bow, LoopDetectorParams{});
    auto hybrid = make_loop_detector("hybrid", hybrid_over(bow));
    EXPECT_EQ(hybrid->name(), "hybrid");
    EXPECT_TRUE(hybrid->uses_global_descriptors());
    EXPECT_FALSE(inner->uses_global_descriptors());
    const auto a = testing::run(*inner, stream);
    const auto b = testing::run(*hybrid, stream);
    ASSERT_FALSE(a.candidates.empty()) << bow;
    EXPECT_EQ(pairs(a.candidates), pairs(b.candidates)) << bow;
    EXPECT_EQ(b.stats.vetoed_by_descriptor, 0U) << bow;
    EXPECT_EQ(b.stats.descriptor_pairs, a.candidates.size()) << bow;
    EXPECT_EQ(b.stats.queries, a.stats.queries) << bow;
    for (const auto& c : b.candidates)
      EXPECT_EQ(stream.place[c.query.value()], stream.place[c.match.value()]);
  }
}

// A revisit that BoW believes but whose whole-image appearance differs (the same ORB words, another
// room) is vetoed: every candidate pair is farther apart than max_distance_sq.
TEST(HybridLoopDetector, VetoesCandidatesThatLookDifferent) {
  for (const std::string bow : {"bow-keyframe", "bow-sequence"}) {
    auto stream = make_stream(revisit_path(), 8, 11);
    std::mt19937 rng(9);
    for (auto& kf : stream.keyframes) kf.global = random_unit(rng);  // nothing looks like anything
    auto inner = make_loop_detector(bow, LoopDetectorParams{});
    auto hybrid = make_loop_detector("hybrid", hybrid_over(bow));
    const auto a = testing::run(*inner, stream);
    const auto b = testing::run(*hybrid, stream);
    ASSERT_FALSE(a.candidates.empty()) << bow;
    EXPECT_TRUE(b.candidates.empty()) << bow;
    EXPECT_EQ(b.stats.vetoed_by_descriptor, a.candidates.size()) << bow;
    EXPECT_EQ(b.stats.candidates, 0U) << bow;
  }
}

// Within one query's candidates, verification sees the most alike first: distances never decrease.
TEST(HybridLoopDetector, OrdersEachQuerysCandidatesByDescriptorDistance) {
  auto stream = make_stream(revisit_path(), 8, 11);
  describe_by_place(stream, 5, 0.6f);  // enough noise that BoW's order and descriptor order differ
  LoopDetectorParams p = hybrid_over("bow-keyframe");
  p.min_consistency = 1;  // more candidates per query
  p.hybrid.max_distance_sq = 4.0;
  auto hybrid = make_loop_detector("hybrid", p);
  testing::TemporalView view(stream, 4);
  std::size_t multi = 0;
  for (const auto& kf : stream.keyframes) {
    view.set_newest(kf.id);
    const auto cs = hybrid->detect(kf, view);
    if (cs.size() > 1) ++multi;
    for (std::size_t i = 1; i < cs.size(); ++i) {
      const auto& q = stream.keyframes[cs[i].query.value()].global;
      const float before = (q - stream.keyframes[cs[i - 1].match.value()].global).squaredNorm();
      const float now = (q - stream.keyframes[cs[i].match.value()].global).squaredNorm();
      EXPECT_LE(before, now) << "keyframe " << kf.id.value();
    }
  }
  EXPECT_GT(multi, 0U) << "no query had two candidates: the test checks nothing";
}

// Keyframes without a descriptor (a model that failed on one image) leave the decision to BoW.
TEST(HybridLoopDetector, UndescribedCandidatesAreKeptAsBowFoundThem) {
  auto stream = make_stream(revisit_path(), 8, 11);
  for (auto& kf : stream.keyframes) kf.global.resize(0);
  auto inner = make_loop_detector("bow-keyframe", LoopDetectorParams{});
  auto hybrid = make_loop_detector("hybrid", hybrid_over("bow-keyframe"));
  const auto a = testing::run(*inner, stream);
  const auto b = testing::run(*hybrid, stream);
  ASSERT_FALSE(a.candidates.empty());
  EXPECT_EQ(pairs(a.candidates), pairs(b.candidates));
  EXPECT_EQ(b.stats.descriptor_pairs, 0U);
}

// Keyframes without a descriptor (half of them here) yield candidates that BoW alone ranks: they come
// after every described candidate of the same query, and are counted.
TEST(HybridLoopDetector, UndescribedCandidatesComeAfterTheDescribedOnes) {
  auto stream = make_stream(revisit_path(), 8, 11);
  describe_by_place(stream, 5, 0.3f);
  for (std::size_t k = 1; k < stream.keyframes.size(); k += 2) stream.keyframes[k].global.resize(0);
  LoopDetectorParams p = hybrid_over("bow-keyframe");
  p.min_consistency = 1;
  auto hybrid = make_loop_detector("hybrid", p);
  testing::TemporalView view(stream, 4);
  std::size_t mixed = 0, undescribed = 0;
  const auto described = [&](const LoopCandidate& c) {
    return stream.keyframes[c.query.value()].global.size() > 0 &&
           stream.keyframes[c.match.value()].global.size() > 0;
  };
  for (const auto& kf : stream.keyframes) {
    view.set_newest(kf.id);
    const auto cs = hybrid->detect(kf, view);
    bool seen_undescribed = false, seen_described = false;
    for (const auto& c : cs) {
      if (!described(c)) {
        seen_undescribed = true;
        ++undescribed;
      } else {
        seen_described = true;
        EXPECT_FALSE(seen_undescribed)
            << "a described candidate after an undescribed one, keyframe " << kf.id.value();
      }
    }
    if (seen_described && seen_undescribed) ++mixed;
  }
  EXPECT_GT(undescribed, 0U);
  EXPECT_GT(mixed, 0U) << "no query mixed both kinds: the ordering was not exercised";
  EXPECT_EQ(hybrid->stats().undescribed_candidates, undescribed);
}

// The YAML section loop_closing.detection.hybrid: keys, choices and ranges.
TEST(HybridLoopDetector, ParamsFromYaml) {
  const auto read = [](const std::string& text) {
    return LoopDetectorParams::from_yaml(sp::ConfigReader::from_string(text, "test.yaml"));
  };
  const LoopDetectorParams p = read("method: hybrid\nhybrid:\n  bow: bow-keyframe\n  max_distance_sq: 0.8\n");
  EXPECT_EQ(p.method, "hybrid");
  EXPECT_EQ(p.hybrid.bow, "bow-keyframe");
  EXPECT_DOUBLE_EQ(p.hybrid.max_distance_sq, 0.8);
  EXPECT_EQ(read("method: hybrid\n").hybrid.bow, HybridParams{}.bow);
  EXPECT_THROW(read("hybrid:\n  bow: netvlad\n"), sp::ConfigError);
  EXPECT_THROW(read("hybrid:\n  max_distance_sq: 5\n"), sp::ConfigError);
}

TEST(HybridLoopDetector, ParamsAreValidated) {
  LoopDetectorParams p;
  p.hybrid.bow = "netvlad";
  EXPECT_THROW(make_loop_detector("hybrid", p), Error);
  p.hybrid.bow = "bow-sequence";
  p.hybrid.max_distance_sq = 0.0;
  EXPECT_THROW(make_loop_detector("hybrid", p), Error);
  p.hybrid.max_distance_sq = 4.5;
  EXPECT_THROW(make_loop_detector("hybrid", p), Error);
}

}  // namespace
}  // namespace sp::loop
