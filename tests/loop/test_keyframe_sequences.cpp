#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "stillpoint/common/error.hpp"
#include "stillpoint/loop/keyframe_sequences.hpp"
#include "stillpoint/loop/loop_closer.hpp"

namespace sp::loop {
namespace {

using namespace map::literals;

Eigen::Matrix3d yaw(double a) {
  return Eigen::AngleAxisd(a, Eigen::Vector3d(0.3, 1.0, 0.2).normalized()).toRotationMatrix();
}

BowVector one_word(WordId w) { return BowVector::from_entries({{w, 1.0}}); }

// Feeds keyframes whose consecutive rotation steps are `steps` (rad); returns closed sequence sizes.
std::vector<std::size_t> segment(const std::vector<double>& steps, const SequenceParams& p,
                                 bool flush = true) {
  SequenceSegmenter seg(p);
  std::vector<std::size_t> sizes;
  double a = 0.2;
  std::uint64_t id = 0;
  auto feed = [&](double angle) {
    if (auto s = seg.add(KeyframeId{id}, yaw(angle), one_word(static_cast<WordId>(id))))
      sizes.push_back(s->keyframes.size());
    ++id;
  };
  feed(a);
  for (double st : steps) feed(a += st);
  if (flush) {
    if (auto s = seg.flush()) sizes.push_back(s->keyframes.size());
  }
  return sizes;
}

TEST(RotationAngle, MatchesAxisAngle) {
  const Eigen::Matrix3d R1 = yaw(0.7);
  const Eigen::Matrix3d R2 = Eigen::AngleAxisd(0.25, Eigen::Vector3d::UnitX()).toRotationMatrix() * R1;
  EXPECT_NEAR(rotation_angle(R1, R2), 0.25, 1e-9);
  EXPECT_NEAR(rotation_angle(R2, R1), 0.25, 1e-9);
  EXPECT_NEAR(rotation_angle(R1, R1), 0.0, 1e-6);
  EXPECT_NEAR(rotation_angle(Eigen::Matrix3d::Identity(), yaw(M_PI)), M_PI, 1e-6);
}

SequenceParams level() {
  SequenceParams p;
  p.trigger = "level";
  return p;
}

// The paper's rules (§III-B prose), default trigger "rising-edge". θ1 = the previous step, θ2 = the step
// to the new keyframe, θ_T = 0.1, L_T = 15.

TEST(SequenceSegmenterPaper, SustainedTurnIsOneSequence) {
  const SequenceParams p;
  EXPECT_EQ(p.trigger, "rising-edge");
  // Seven 0.5 rad steps: θ1 > θ_T and θ2 > θ_T every time, no edge: one sequence of 8 keyframes.
  EXPECT_EQ(segment(std::vector<double>(7, 0.5), p), (std::vector<std::size_t>{8}));
  // Still, then a sustained turn: the turn's first keyframe starts a sequence and the whole turn stays in it.
  EXPECT_EQ(segment({0.01, 0.01, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5}, p), (std::vector<std::size_t>{3, 6}));
}

TEST(SequenceSegmenterPaper, RisingEdgeStartsANewSequenceFallingEdgeDoesNot) {
  const SequenceParams p;
  // θ1 = 0.01 < θ_T, θ2 = 0.5 > θ_T at keyframe 3: {0,1,2} closes, 3 starts the next; the turn ends at
  // keyframe 4 (θ1 = 0.5 > θ_T, θ2 = 0.01 < θ_T): it joins.
  SequenceSegmenter seg(p);
  double a = 0.0;
  std::uint64_t id = 0;
  std::vector<std::vector<KeyframeId>> closed;
  for (double st : {0.0, 0.01, 0.01, 0.5, 0.01, 0.01}) {
    a += st;
    if (auto s = seg.add(KeyframeId{id}, yaw(a), one_word(static_cast<WordId>(id))))
      closed.push_back(s->keyframes);
    ++id;
  }
  ASSERT_EQ(closed.size(), 1U);
  EXPECT_EQ(closed[0], (std::vector<KeyframeId>{0_kf, 1_kf, 2_kf}));
  EXPECT_EQ(seg.open_keyframes(), (std::vector<KeyframeId>{3_kf, 4_kf, 5_kf}));
  // A turn from the start, then still: the falling edge never starts a sequence.
  EXPECT_EQ(segment({0.5, 0.5, 0.01, 0.01}, p), (std::vector<std::size_t>{5}));
  // Two turns: a sequence per rising edge.
  EXPECT_EQ(segment({0.01, 0.5, 0.5, 0.01, 0.01, 0.3, 0.01}, p), (std::vector<std::size_t>{2, 4, 2}));
  // Just below / just above θ_T.
  EXPECT_EQ(segment({0.0999, 0.0999, 0.1001, 0.0999, 0.1001}, p), (std::vector<std::size_t>{3, 2, 1}));
  // Slow drift never closes on the angle between consecutive keyframes...
  EXPECT_EQ(segment(std::vector<double>(9, 0.05), p), (std::vector<std::size_t>{10}));
  // ...but does when measured against the sequence's first keyframe (θ crosses θ_T once per sequence).
  SequenceParams first = p;
  first.angle_to_first = true;
  EXPECT_EQ(segment(std::vector<double>(9, 0.06), first), (std::vector<std::size_t>{2, 2, 2, 2, 2}));
}

TEST(SequenceSegmenterPaper, LengthAboveLTAlwaysCloses) {
  const SequenceParams p;
  // No edge at all (still, or a sustained turn): sequences are cut at L_T = 15 keyframes.
  EXPECT_EQ(segment(std::vector<double>(39, 0.01), p), (std::vector<std::size_t>{15, 15, 10}));
  EXPECT_EQ(segment(std::vector<double>(20, 0.5), p), (std::vector<std::size_t>{15, 6}));
  SequenceParams four = p;
  four.max_length = 4;
  EXPECT_EQ(segment(std::vector<double>(9, 0.0), four), (std::vector<std::size_t>{4, 4, 2}));
}

TEST(SequenceSegmenterPaper, LengthBelowTwoNeverCloses) {
  SequenceParams p;
  p.max_length = 3;
  // Keyframe 3 starts a sequence (L_T cap); keyframe 4 is a rising edge (θ1 = 0.01, θ2 = 0.5) but the
  // open sequence holds one keyframe (L_S = 1 < 2): it joins.
  EXPECT_EQ(segment({0.01, 0.01, 0.01, 0.5}, p), (std::vector<std::size_t>{3, 2}));
  // The second keyframe of a run always joins the first (no θ1 yet, and L_S = 1).
  EXPECT_EQ(segment({0.5}, SequenceParams{}), (std::vector<std::size_t>{2}));
  // Without the rule (short_sequences_grow off) the rising edge closes the one-keyframe sequence.
  p.short_sequences_grow = false;
  EXPECT_EQ(segment({0.01, 0.01, 0.01, 0.5}, p), (std::vector<std::size_t>{3, 1, 1}));
}

// Our first reading, "level": every step >= θ_T closes (loop_closing.sequence_trigger: level).

TEST(SequenceSegmenterLevel, AnglesJustBelowAndAboveThreshold) {
  SequenceParams p = level();
  // 0.0999 joins, 0.1001 closes: {0,1,2} {3,4} {5}
  EXPECT_EQ(segment({0.0999, 0.0999, 0.1001, 0.0999, 0.1001}, p), (std::vector<std::size_t>{3, 2, 1}));
  // Slow drift never closes on the angle when measured between consecutive keyframes...
  EXPECT_EQ(segment(std::vector<double>(9, 0.05), p), (std::vector<std::size_t>{10}));
  // ...but does when measured against the first keyframe of the sequence.
  p.angle_to_first = true;
  EXPECT_EQ(segment(std::vector<double>(9, 0.05), p), (std::vector<std::size_t>{2, 2, 2, 2, 2}));
}

TEST(SequenceSegmenterLevel, LengthCapAndIds) {
  SequenceParams p = level();
  EXPECT_EQ(segment(std::vector<double>(39, 0.01), p), (std::vector<std::size_t>{15, 15, 10}));
  p.max_length = 4;
  EXPECT_EQ(segment(std::vector<double>(9, 0.0), p), (std::vector<std::size_t>{4, 4, 2}));
  p.short_sequences_grow = false;  // the strict reading: a one-keyframe sequence closes on a turn
  SequenceSegmenter seg(p);
  EXPECT_FALSE(seg.add(7_kf, yaw(0), one_word(1)).has_value());
  const auto closed = seg.add(8_kf, yaw(1.0), one_word(2));
  ASSERT_TRUE(closed.has_value());
  EXPECT_EQ(closed->id, 0U);
  EXPECT_EQ(closed->keyframes, (std::vector<KeyframeId>{7_kf}));
  EXPECT_EQ(seg.open_id(), 1U);
  EXPECT_EQ(seg.open_keyframes(), (std::vector<KeyframeId>{8_kf}));
}

TEST(SequenceSegmenterLevel, ShortSequencesTakeTheNextKeyframeWhateverTheTurn) {
  SequenceParams p = level();  // short_sequences_grow by default, min_length 2
  // Fast turns everywhere: pairs instead of singletons (the paper's rule gives one sequence, above).
  EXPECT_EQ(segment(std::vector<double>(7, 0.5), p), (std::vector<std::size_t>{2, 2, 2, 2}));
  // A fast turn between two slow stretches: the keyframe after the turn still starts a sequence.
  EXPECT_EQ(segment({0.01, 0.01, 0.5, 0.01, 0.01}, p), (std::vector<std::size_t>{3, 3}));
  p.short_sequences_grow = false;
  EXPECT_EQ(segment(std::vector<double>(7, 0.5), p), (std::vector<std::size_t>(8, 1)));
  p.short_sequences_grow = true;
  p.min_length = 3;
  EXPECT_EQ(segment(std::vector<double>(7, 0.5), p), (std::vector<std::size_t>{3, 3, 2}));
}

TEST(SequenceSegmenter, SequenceVectorIsNormalisedSum) {
  SequenceSegmenter seg(SequenceParams{});
  seg.add(0_kf, yaw(0), BowVector::from_entries({{1, 3.0}, {2, 1.0}}));  // normalised: .75 .25
  seg.add(1_kf, yaw(0.01), BowVector::from_entries({{2, 10.0}}));        // normalised: 1
  const auto s = seg.flush();
  ASSERT_TRUE(s.has_value());
  EXPECT_NEAR(s->bow.l1_norm(), 1.0, 1e-12);
  EXPECT_NEAR(s->bow.weight(1), 0.375, 1e-12);
  EXPECT_NEAR(s->bow.weight(2), 0.625, 1e-12);
  EXPECT_FALSE(seg.flush().has_value());
}

TEST(SequenceParams, RejectsBadValues) {
  SequenceParams p;
  p.min_length = 20;
  EXPECT_THROW(SequenceSegmenter{p}, sp::Error);
  p = SequenceParams{};
  p.theta_t = 0.0;
  EXPECT_THROW(p.validate(), sp::Error);
  const auto r = sp::ConfigReader::from_string("theta_t: 0.2\nmax_length: 10\nmin_length: 3\n", "test.yaml");
  const SequenceParams q = SequenceParams::from_yaml(r);
  r.finish();
  EXPECT_DOUBLE_EQ(q.theta_t, 0.2);
  EXPECT_EQ(q.max_length, 10);
  EXPECT_EQ(q.min_length, 3);
  EXPECT_THROW(SequenceParams::from_yaml(sp::ConfigReader::from_string("max_length: 0\n", "bad.yaml")),
               sp::ConfigError);
  EXPECT_EQ(q.trigger, "rising-edge");
  EXPECT_EQ(SequenceParams::from_yaml(sp::ConfigReader::from_string("trigger: level\n", "t.yaml")).trigger,
            "level");
  EXPECT_THROW(SequenceParams::from_yaml(sp::ConfigReader::from_string("trigger: edge\n", "bad.yaml")),
               sp::ConfigError);
  p = SequenceParams{};
  p.trigger = "falling";
  EXPECT_THROW(p.validate(), sp::Error);
}

TEST(SequenceParams, SystemKeySequenceTrigger) {
  const auto read = [](const std::string& text) {
    const auto r = sp::ConfigReader::from_string(text, "loop.yaml");
    const LoopClosingConfig c = LoopClosingConfig::from_yaml(r);
    r.finish();
    return c.detection.sequence.trigger;
  };
  EXPECT_EQ(read("detector: bow-sequence\n"), "rising-edge");
  EXPECT_EQ(read("sequence_trigger: level\n"), "level");
  EXPECT_EQ(read("sequence_trigger: rising-edge\n"), "rising-edge");
  EXPECT_THROW(read("sequence_trigger: both\n"), sp::ConfigError);
  EXPECT_THROW(read("sequence_trigger: level\ndetection:\n  sequence:\n    trigger: level\n"),
               sp::ConfigError);
}

}  // namespace
}  // namespace sp::loop
