#include <gtest/gtest.h>

#include <random>

#include "stillpoint/common/error.hpp"
#include "stillpoint/loop/global_descriptor_detector.hpp"
#include "synthetic_stream.hpp"

namespace sp::loop {
namespace {

using testing::make_stream;
using testing::revisit_path;

// Each place gets a random unit "appearance"; adjacent places blend half of their neighbour's (a
// continuous path), and every keyframe adds noise, so neighbours are closer than unrelated places.
void attach_descriptors(testing::Stream& s, std::uint32_t seed, float noise) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> n(0.f, 1.f);
  const auto random_unit = [&] {
    Eigen::VectorXf v(256);  // random directions in 256-D are nearly orthogonal
    for (int i = 0; i < 256; ++i) v(i) = n(rng);
    return Eigen::VectorXf(v.normalized());
  };
  std::vector<Eigen::VectorXf> base;
  for (int p = 0; p < 32; ++p) base.push_back(random_unit());
  for (std::size_t k = 0; k < s.keyframes.size(); ++k) {
    const auto p = static_cast<std::size_t>(s.place[k]);
    Eigen::VectorXf d = base[p] + 0.5f * base[p + 1] + noise * random_unit();
    s.keyframes[k].global = d.normalized();
  }
}

testing::RunResult run_global(const testing::Stream& stream, LoopDetectorParams params = {}) {
  auto det = make_loop_detector("netvlad", params);
  EXPECT_EQ(det->name(), "netvlad");
  return testing::run(*det, stream);
}

TEST(GlobalDescriptorLoopDetector, FindsPlantedRevisit) {
  auto stream = make_stream(revisit_path(), 8, 11);
  attach_descriptors(stream, 5, 0.3f);
  const auto r = run_global(stream);
  ASSERT_FALSE(r.candidates.empty());
  for (const auto& c : r.candidates) {
    EXPECT_GE(c.query.value(), 80U) << "a candidate before the revisit";
    EXPECT_EQ(stream.place[c.query.value()], stream.place[c.match.value()]) << "wrong place";
    EXPECT_GT(c.score, 0.0);
    EXPECT_LE(c.score, 1.0);
  }
  EXPECT_EQ(r.stats.keyframes, stream.keyframes.size());
  EXPECT_GT(r.stats.queries, 0U);
}

TEST(GlobalDescriptorLoopDetector, NoCandidateOnAPathWithoutRevisit) {
  std::vector<int> places;
  for (int p = 0; p < 15; ++p) places.push_back(p);
  auto stream = make_stream(places, 8, 12);
  attach_descriptors(stream, 6, 0.3f);
  EXPECT_TRUE(run_global(stream).candidates.empty());
}

TEST(GlobalDescriptorLoopDetector, AbsoluteDistanceLimitRejectsEverything) {
  auto stream = make_stream(revisit_path(), 8, 11);
  attach_descriptors(stream, 5, 0.3f);
  LoopDetectorParams p;
  p.global.max_distance_sq = 1e-4;  // nothing is that close
  EXPECT_TRUE(run_global(stream, p).candidates.empty());
}

TEST(GlobalDescriptorLoopDetector, ConsistencyDelaysAcceptance) {
  auto stream = make_stream(revisit_path(), 8, 11);
  attach_descriptors(stream, 5, 0.3f);
  LoopDetectorParams once;
  once.min_consistency = 1;
  LoopDetectorParams thrice;
  thrice.min_consistency = 3;
  const auto a = run_global(stream, once);
  const auto b = run_global(stream, thrice);
  ASSERT_FALSE(a.candidates.empty());
  ASSERT_FALSE(b.candidates.empty());
  EXPECT_LT(a.candidates.front().query, b.candidates.front().query);
}

TEST(GlobalDescriptorLoopDetector, RejectsKeyframesWithoutDescriptorOrOfAnotherSize) {
  auto det = make_loop_detector("netvlad", LoopDetectorParams{});
  auto stream = make_stream({0, 1}, 2, 3);
  testing::TemporalView view(stream, 4);
  KeyframeInfo missing = stream.keyframes[0];
  EXPECT_THROW(det->detect(missing, view), Error);
  KeyframeInfo a = stream.keyframes[0];
  a.global = Eigen::VectorXf::Ones(8).normalized();
  det->detect(a, view);
  KeyframeInfo b = stream.keyframes[1];
  b.global = Eigen::VectorXf::Ones(16).normalized();
  view.set_newest(KeyframeId{1});
  EXPECT_THROW(det->detect(b, view), Error);
}

TEST(GlobalDescriptorLoopDetector, ParamsAreValidated) {
  LoopDetectorParams p;
  p.global.max_distance_sq = 5.0;
  EXPECT_THROW(make_loop_detector("netvlad", p), Error);
  p.global.max_distance_sq = 1.0;
  p.global.top_k = 0;
  EXPECT_THROW(make_loop_detector("netvlad", p), Error);
}

}  // namespace
}  // namespace sp::loop
