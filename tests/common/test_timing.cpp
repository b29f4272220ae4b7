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
