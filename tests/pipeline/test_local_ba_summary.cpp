// The run's local-BA summary (stats.json "local_ba"): solved, aborted and dropped BAs are counted apart,
// and a keyframe move is counted against each threshold it exceeds, from the BAs that were solved only.
#include <gtest/gtest.h>

#include "stillpoint/pipeline/local_mapping_stage.hpp"

namespace sp::pipeline {
namespace {

mapping::LocalMappingStats solved(double move_m, bool dropped = false) {
  mapping::LocalMappingStats s;
  s.ba_solved = true;
  s.ba_dropped = dropped;
  s.ba_largest_keyframe_move_m = move_m;
  return s;
}

TEST(LocalBASummary, CountsEachMoveAgainstEveryThresholdItExceeds) {
  LocalBASummary summary;
  summary.add(solved(0.002));
  summary.add(solved(0.02));
  summary.add(solved(0.05, /*dropped=*/true));
  summary.add(solved(0.12));
  EXPECT_EQ(summary.solved, 4u);
  EXPECT_EQ(summary.dropped, 1u);
  EXPECT_EQ(summary.moves_over_1cm, 3u);
  EXPECT_EQ(summary.moves_over_3cm, 2u);
  EXPECT_EQ(summary.moves_over_10cm, 1u);
  EXPECT_DOUBLE_EQ(summary.largest_keyframe_move_m, 0.12);
}

TEST(LocalBASummary, AnAbortedOrSkippedBAMovesNothing) {
  LocalBASummary summary;
  mapping::LocalMappingStats aborted;
  aborted.ba_aborted = true;
  aborted.ba_largest_keyframe_move_m = 0.5;  // never measured for an aborted BA; must not count
  summary.add(aborted);
  summary.add(mapping::LocalMappingStats{});  // no BA at all (too few keyframes)
  EXPECT_EQ(summary.aborted, 1u);
  EXPECT_EQ(summary.solved, 0u);
  EXPECT_EQ(summary.moves_over_1cm, 0u);
  EXPECT_DOUBLE_EQ(summary.largest_keyframe_move_m, 0.0);
}

}  // namespace
}  // namespace sp::pipeline
