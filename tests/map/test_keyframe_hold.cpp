// Culling holds: a held keyframe cannot be erased; KeyframeHold releases what it holds when it is
// released, moved from or destroyed, and never holds a culled keyframe.
#include <gtest/gtest.h>

#include "stillpoint/map/keyframe_hold.hpp"

namespace sp::map {
namespace {

using namespace sp::map::literals;

struct Chain {
  Map map;
  std::vector<KeyframeId> kfs;  // the first is the root (never erased); the others have parents
  Chain() {
    MapView v = map.view();
    for (int k = 0; k < 3; ++k) {
      Keyframe kf;
      kf.frame_index = static_cast<std::size_t>(k);
      kfs.push_back(v.add_keyframe(std::move(kf)));
    }
    for (std::size_t k = 1; k < kfs.size(); ++k) {
      v.keyframe(kfs[k])->parent = kfs[k - 1];
      v.keyframe(kfs[k - 1])->children.insert(kfs[k]);
    }
  }
  int holds(KeyframeId k) {
    MapView v = map.view();
    return v.keyframe(k)->culling_holds;
  }
};

TEST(KeyframeHold, RefusesErasureUntilReleasedByItsDestructor) {
  Chain c;
  {
    KeyframeHold hold(c.map);
    {
      MapView v = c.map.view();
      ASSERT_TRUE(hold.add(v, c.kfs[1]));
      EXPECT_FALSE(v.erase_keyframe(c.kfs[1]));
      EXPECT_FALSE(v.keyframe(c.kfs[1])->bad);
    }
    EXPECT_EQ(hold.keyframes(), std::vector<KeyframeId>{c.kfs[1]});
  }
  EXPECT_EQ(c.holds(c.kfs[1]), 0);
  MapView v = c.map.view();
  EXPECT_TRUE(v.erase_keyframe(c.kfs[1]));
}

TEST(KeyframeHold, AMovedHoldIsReleasedOnceByItsNewOwner) {
  Chain c;
  KeyframeHold a(c.map);
  {
    MapView v = c.map.view();
    ASSERT_TRUE(a.add(v, c.kfs[1]));
    ASSERT_TRUE(a.add(v, c.kfs[2]));
  }
  {
    KeyframeHold b(std::move(a));
    EXPECT_TRUE(a.keyframes().empty());  // NOLINT(bugprone-use-after-move): moved-from is empty
    EXPECT_EQ(c.holds(c.kfs[2]), 1);
  }
  EXPECT_EQ(c.holds(c.kfs[1]), 0);
  EXPECT_EQ(c.holds(c.kfs[2]), 0);
}

TEST(KeyframeHold, NeverHoldsACulledKeyframe) {
  Chain c;
  KeyframeHold hold(c.map);
  MapView v = c.map.view();
  ASSERT_TRUE(v.erase_keyframe(c.kfs[2]));
  EXPECT_FALSE(hold.add(v, c.kfs[2]));
  EXPECT_FALSE(hold.add(v, 999_kf));
  EXPECT_TRUE(hold.keyframes().empty());
  EXPECT_TRUE(v.hold_keyframe(c.kfs[0]));  // the root may be held (it is never culled anyway)
  v.release_keyframe(c.kfs[0]);
}

}  // namespace
}  // namespace sp::map
