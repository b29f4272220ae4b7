#include <gtest/gtest.h>

#include <vector>

#include "stillpoint/common/timing.hpp"

namespace sp {
namespace {

TEST(Timing, SummaryOfKnownSamples) {
  const auto s = summarize({5, 1, 4, 2, 3});
  EXPECT_EQ(s.count, 5u);
  EXPECT_DOUBLE_EQ(s.total, 15.0);
  EXPECT_DOUBLE_EQ(s.mean, 3.0);
  EXPECT_DOUBLE_EQ(s.median, 3.0);
  EXPECT_DOUBLE_EQ(s.p95, 4.8);  // linear interpolation between 4 and 5
  EXPECT_DOUBLE_EQ(s.max, 5.0);
}

TEST(PlaybackClock, FramesAreDueAtTheirRecordedTimeScaledByTheRate) {
  using namespace std::chrono_literals;
  PlaybackClock clock(2.0);  // twice the recorded pace
  const auto t0 = PlaybackClock::Clock::now();
  EXPECT_EQ(clock.due_in(100.0, t0), PlaybackClock::Clock::duration::zero());  // the first frame anchors
  // Recorded 1 s after the first: due 0.5 s after it; 0.1 s have passed.
  const auto wait = clock.due_in(101.0, t0 + 100ms);
  EXPECT_NEAR(std::chrono::duration<double>(wait).count(), 0.4, 1e-6);
  // A frame whose time has passed (tracking fell behind) is not delayed.
  EXPECT_EQ(clock.due_in(100.5, t0 + 1s), PlaybackClock::Clock::duration::zero());
  // Nor one stamped before the first (an unordered sequence).
  EXPECT_EQ(clock.due_in(99.0, t0), PlaybackClock::Clock::duration::zero());
}

TEST(PlaybackClock, RateZeroNeverWaits) {
  using namespace std::chrono_literals;
  PlaybackClock clock(0.0);
  const auto t0 = PlaybackClock::Clock::now();
  EXPECT_EQ(clock.due_in(0.0, t0), PlaybackClock::Clock::duration::zero());
  EXPECT_EQ(clock.due_in(50.0, t0 + 1ms), PlaybackClock::Clock::duration::zero());
}

TEST(Timing, EmptySummaryIsZero) {
  const auto s = summarize({});
  EXPECT_EQ(s.count, 0u);
  EXPECT_DOUBLE_EQ(s.median, 0.0);
}

TEST(Timing, PeakRssIsPositiveOnLinux) { EXPECT_GT(peak_rss_mib(), 0.0); }

TEST(Timing, CurrentRssFollowsAnAllocationAndStaysBelowThePeak) {
  const double before = current_rss_mib();
  EXPECT_GT(before, 0.0);
  // 64 MiB written (so resident, not just reserved) must show up in VmRSS.
  std::vector<char> block(64u << 20, 1);
  const double during = current_rss_mib();
  EXPECT_GT(during, before + 32.0) << "VmRSS did not grow with a 64 MiB touched block";
  EXPECT_LE(during, peak_rss_mib() + 1e-6);
  EXPECT_EQ(block[block.size() / 2], 1);
}

}  // namespace
}  // namespace sp
