// ObservationList replaces std::map<KeyframeId, int> for a point's observations: it must answer and
// iterate exactly as the std::map did, through any sequence of inserts and erases.
#include <gtest/gtest.h>

#include <map>
#include <random>
#include <vector>

#include "stillpoint/map/observation_list.hpp"

namespace sp::map {
namespace {

using namespace literals;

void expect_same(const ObservationList& list, const std::map<KeyframeId, int>& reference) {
  ASSERT_EQ(list.size(), reference.size());
  EXPECT_EQ(list.empty(), reference.empty());
  auto it = reference.begin();
  for (const auto& [kf, feature] : list) {  // same order: by increasing keyframe id
    ASSERT_EQ(kf, it->first);
    ASSERT_EQ(feature, it->second);
    ++it;
  }
}

TEST(ObservationList, BehavesAsTheStdMapItReplacesUnderRandomEdits) {
  std::mt19937 rng(7);
  std::uniform_int_distribution<std::uint64_t> keyframe(1, 40);
  std::uniform_int_distribution<int> feature(0, 999), op(0, 5);
  ObservationList list;
  std::map<KeyframeId, int> reference;
  for (int step = 0; step < 5000; ++step) {
    const KeyframeId kf{keyframe(rng)};
    const int f = feature(rng);
    switch (op(rng)) {
      case 0: {
        const auto [it, inserted] = list.emplace(kf, f);
        const auto [rit, rinserted] = reference.emplace(kf, f);
        EXPECT_EQ(inserted, rinserted);
        EXPECT_EQ(it->second, rit->second);
        break;
      }
      case 1:
        list[kf] = f;
        reference[kf] = f;
        break;
      case 2:
        EXPECT_EQ(list.erase(kf), reference.erase(kf));
        break;
      case 3: {
        const auto it = list.find(kf);
        const auto rit = reference.find(kf);
        ASSERT_EQ(it == list.end(), rit == reference.end());
        if (it != list.end()) {
          EXPECT_EQ(it->second, rit->second);
          EXPECT_EQ(list.at(kf), reference.at(kf));
          list.erase(it);
          reference.erase(rit);
        }
        break;
      }
      case 4:
        EXPECT_EQ(list.contains(kf), reference.contains(kf));
        break;
      default:
        if (step % 500 == 0) {
          list.clear();
          reference.clear();
        }
    }
    expect_same(list, reference);
  }
}

TEST(ObservationList, AtThrowsForAKeyframeNotObservedAndTheFirstEntryIsTheLowestId) {
  ObservationList list{{9_kf, 3}, {2_kf, 5}, {9_kf, 7}};  // a repeated keyframe keeps its first feature
  ASSERT_EQ(list.size(), 2u);
  EXPECT_EQ(list.begin()->first, 2_kf);
  EXPECT_EQ(list.at(9_kf), 3);
  EXPECT_THROW((void)list.at(4_kf), std::out_of_range);
  const ObservationList copy = list;
  EXPECT_EQ(copy, list);
  list[4_kf];  // operator[] inserts a zero feature, as std::map's does
  EXPECT_EQ(list.at(4_kf), 0);
  EXPECT_FALSE(copy == list);
}

}  // namespace
}  // namespace sp::map
