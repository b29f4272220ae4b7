// MapReader, the read-only view, and the LockHoldClock that times views (the tracking thread's lock
// time per frame).
#include <gtest/gtest.h>

#include <thread>
#include <type_traits>

#include "stillpoint/map/map.hpp"

namespace sp::map {
namespace {

TEST(MapReader, ReadsWhatAViewWroteAndHandsOutConstRecordsOnly) {
  Map map;
  PointId pid = kNoPoint;
  {
    MapView view = map.view();
    pid = view.add_point(MapPoint{});
  }
  MapReader reader = map.reader();
  static_assert(std::is_same_v<decltype(reader.point(pid)), const MapPoint*>);
  static_assert(std::is_same_v<decltype(reader.keyframe(KeyframeId{1})), const Keyframe*>);
  ASSERT_NE(reader.live_point(pid), nullptr);
  EXPECT_EQ(reader.live_points(), 1u);
  EXPECT_EQ(reader.live_keyframes(), 0u);
}

TEST(LockHoldClock, AddsUpTheHoldsOfTheViewsGivenItAndStartsAgainWhenTaken) {
  Map map;
  LockHoldClock clock;
  {
    MapReader reader = map.reader(&clock);
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  {
    MapView view = map.view(&clock);
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  { MapView untimed = map.view(); }
  const LockHoldClock::Times t = clock.take();
  EXPECT_GE(t.held_ms, 4.0);
  EXPECT_GE(t.waited_ms, 0.0);
  EXPECT_EQ(clock.take().held_ms, 0.0);
}

}  // namespace
}  // namespace sp::map
