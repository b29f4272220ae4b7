#include <gtest/gtest.h>

#include "stillpoint/common/error.hpp"
#include "synthetic_stream.hpp"

namespace sp::loop {
namespace {

using testing::make_stream;
using testing::run;
using namespace map::literals;

std::vector<int> path_with_revisit() {
  std::vector<int> places;
  for (int p = 0; p < 10; ++p) places.push_back(p);
  for (int p : {2, 3, 4, 5}) places.push_back(p);  // the revisit
  places.push_back(6);
  return places;
}

std::vector<int> path_without_revisit() {
  std::vector<int> places;
  for (int p = 0; p < 15; ++p) places.push_back(p);
  return places;
}

void expect_revisit_found(const std::string& method) {
  const auto stream = make_stream(path_with_revisit(), 8, 11);
  auto det = make_loop_detector(method, LoopDetectorParams{});
  const auto r = run(*det, stream);
  ASSERT_FALSE(r.candidates.empty()) << method;
  for (const auto& c : r.candidates) {
    EXPECT_GE(c.query.value(), 80U) << method << ": a candidate before the revisit";
    EXPECT_EQ(stream.place[c.query.value()], stream.place[c.match.value()]) << method << ": wrong place";
    EXPECT_LT(c.match.value(), 80U);
  }
}

TEST(KeyframeLoopDetector, FindsPlantedRevisit) { expect_revisit_found("bow-keyframe"); }
TEST(SequenceLoopDetector, FindsPlantedRevisit) { expect_revisit_found("bow-sequence"); }

TEST(LoopDetectors, NoCandidateWithoutRevisit) {
  for (const char* method : {"bow-keyframe", "bow-sequence"}) {
    const auto stream = make_stream(path_without_revisit(), 8, 12);
    auto det = make_loop_detector(method, LoopDetectorParams{});
    const auto r = run(*det, stream);
    EXPECT_TRUE(r.candidates.empty()) << method << " found " << r.candidates.size();
    EXPECT_GT(r.stats.queries, 0U) << method;
  }
}

TEST(LoopDetectors, SequencesQueryTheDatabaseFarLess) {
  const auto stream = make_stream(path_with_revisit(), 8, 13);
  auto per_kf = make_loop_detector("bow-keyframe", LoopDetectorParams{});
  auto per_seq = make_loop_detector("bow-sequence", LoopDetectorParams{});
  const auto a = run(*per_kf, stream);
  const auto b = run(*per_seq, stream);
  EXPECT_FALSE(a.candidates.empty());
  EXPECT_FALSE(b.candidates.empty());
  EXPECT_EQ(a.stats.keyframes, stream.keyframes.size());
  EXPECT_EQ(per_kf->queries(), a.stats.queries);
  // Sequences of 8 keyframes: about one query per 8 keyframes.
  ASSERT_GT(b.stats.queries, 0U);
  EXPECT_GE(a.stats.queries, 5 * b.stats.queries) << a.stats.queries << " vs " << b.stats.queries;
  EXPECT_LT(b.stats.scored_pairs, a.stats.scored_pairs);
}

TEST(LoopDetectors, ShortSequencesNeverCloseALoop) {
  // Every keyframe turns by more than θ_T and, read as a level trigger, short sequences close at once
  // (the strict reading): all sequences have one keyframe, so nothing is queried.
  auto stream = make_stream(path_with_revisit(), 8, 14);
  for (std::size_t i = 0; i < stream.keyframes.size(); ++i) {
    stream.keyframes[i].R_cw =
        Eigen::AngleAxisd(0.2 * static_cast<double>(i), Eigen::Vector3d::UnitY()).toRotationMatrix();
  }
  LoopDetectorParams strict;
  strict.sequence.short_sequences_grow = false;
  strict.sequence.trigger = "level";
  auto det = make_loop_detector("bow-sequence", strict);
  const auto r = run(*det, stream);
  EXPECT_TRUE(r.candidates.empty());
  EXPECT_EQ(r.stats.queries, 0U);
  // Read literally ("shorter sequences never close"), the same turns give pairs that are queried.
  LoopDetectorParams grow_level;
  grow_level.sequence.trigger = "level";
  auto grow = make_loop_detector("bow-sequence", grow_level);
  EXPECT_GT(run(*grow, stream).stats.queries, 0U);
  // The paper's rising-edge rule: a steady turn has no edge, sequences are cut at L_T and queried.
  auto paper = make_loop_detector("bow-sequence", LoopDetectorParams{});
  EXPECT_GT(run(*paper, stream).stats.queries, 0U);
}

TEST(GroupConsistency, NeedsConsecutiveOverlappingGroups) {
  GroupConsistency c(3);
  EXPECT_EQ(c.update({{1_kf, 2_kf, 3_kf}}), std::vector<bool>{false});
  EXPECT_EQ(c.update({{3_kf, 4_kf}}), std::vector<bool>{false});
  EXPECT_EQ(c.update({{4_kf, 5_kf}, {50_kf}}), (std::vector<bool>{true, false}));
  EXPECT_EQ(c.update({}), std::vector<bool>{});  // a query without candidates breaks the chain
  EXPECT_EQ(c.update({{5_kf, 6_kf}}), std::vector<bool>{false});
}

TEST(KeyframeDatabase, QueryCountsAndErase) {
  KeyframeDatabase db;
  db.add(1, BowVector::from_entries({{1, 1.0}, {2, 1.0}, {3, 1.0}}));
  db.add(2, BowVector::from_entries({{1, 1.0}, {9, 1.0}}));
  db.add(3, BowVector::from_entries({{7, 1.0}}));
  const BowVector q = BowVector::from_entries({{1, 1.0}, {2, 1.0}, {3, 1.0}});
  auto hits = db.query(q, 0.5);
  ASSERT_EQ(hits.size(), 1U);  // id 2 shares 1 word < 0.5 x 3
  EXPECT_EQ(hits[0].id, 1U);
  EXPECT_EQ(hits[0].common_words, 3U);
  EXPECT_NEAR(hits[0].score, 1.0, 1e-12);
  hits = db.query(q, 0.1, [](EntryId id) { return id == 1; });
  ASSERT_EQ(hits.size(), 1U);
  EXPECT_EQ(hits[0].id, 2U);
  db.erase(1);
  EXPECT_FALSE(db.contains(1));
  EXPECT_EQ(db.query(q, 0.5).size(), 1U);
  EXPECT_EQ(db.queries(), 3U);
  EXPECT_EQ(db.size(), 2U);
}

TEST(LoopDetectorFactory, RejectsUnknownMethod) {
  EXPECT_THROW(make_loop_detector("dbow3", LoopDetectorParams{}), sp::Error);
  EXPECT_EQ(make_loop_detector("bow-sequence", LoopDetectorParams{})->name(), "bow-sequence");
  const auto r =
      sp::ConfigReader::from_string("method: bow-sequence\nsequence:\n  max_length: 12\n", "loop.yaml");
  const auto p = LoopDetectorParams::from_yaml(r);
  r.finish();
  EXPECT_EQ(make_loop_detector(p)->name(), "bow-sequence");
  EXPECT_EQ(p.sequence.max_length, 12);
}

}  // namespace
}  // namespace sp::loop
