// Keyframe and point ids are distinct types (issue 15): neither converts to the other nor is made
// from a bare number by accident, and both keep the order, hash and text of the number they hold.
#include <gtest/gtest.h>

#include <type_traits>
#include <unordered_set>

#include "stillpoint/map/types.hpp"

namespace sp::map {
namespace {

using namespace literals;

static_assert(!std::is_convertible_v<KeyframeId, PointId>);
static_assert(!std::is_convertible_v<PointId, KeyframeId>);
static_assert(!std::is_constructible_v<PointId, KeyframeId>);
static_assert(!std::is_convertible_v<std::uint64_t, KeyframeId>);  // explicit only: KeyframeId{3}
static_assert(!std::is_convertible_v<KeyframeId, std::uint64_t>);
static_assert(std::is_trivially_copyable_v<KeyframeId> && sizeof(KeyframeId) == sizeof(std::uint64_t));

TEST(Ids, NoneIsZeroAndIdsOrderAndPrintAsTheirNumbers) {
  EXPECT_EQ(kNoKeyframe.value(), 0u);
  EXPECT_EQ(kNoPoint, PointId{});
  EXPECT_LT(3_kf, 12_kf);
  EXPECT_EQ(KeyframeId{7}, 7_kf);
  EXPECT_EQ(fmt::format("{}", 42_pt), "42");
  EXPECT_EQ(std::hash<PointId>{}(42_pt), std::hash<std::uint64_t>{}(42));  // hash containers keep their order
  std::unordered_set<KeyframeId> set{1_kf, 2_kf, 1_kf};
  EXPECT_EQ(set.size(), 2u);
}

}  // namespace
}  // namespace sp::map
