// IdIndex against std::unordered_map under long random sequences of inserts, overwrites, erases, lookups
// and clears (dense and sparse id ranges, so probe runs wrap around the table and erases shift them).
#include <gtest/gtest.h>

#include <random>
#include <stdexcept>
#include <unordered_map>

#include "stillpoint/common/id_index.hpp"

namespace sp {
namespace {

// Every key of the reference, and every id of a dense range (or a sample of a sparse one), answer alike.
void check_same(const IdIndex& index, const std::unordered_map<std::uint64_t, std::size_t>& ref,
                std::uint64_t max_id, std::mt19937_64& rng) {
  ASSERT_EQ(index.size(), ref.size());
  for (const auto& [id, value] : ref) {
    const std::size_t* v = index.find(id);
    ASSERT_NE(v, nullptr) << "id " << id;
    ASSERT_EQ(*v, value) << "id " << id;
  }
  std::uniform_int_distribution<std::uint64_t> pick(1, max_id);
  for (std::uint64_t k = 1; k <= 10000; ++k) {
    const std::uint64_t id = max_id <= 10000 ? k : pick(rng);
    if (id > max_id) break;
    ASSERT_EQ(index.find(id) != nullptr, ref.count(id) == 1) << "id " << id;
  }
}

class IdIndexRandom : public ::testing::TestWithParam<std::uint64_t> {};

TEST_P(IdIndexRandom, BehavesAsAnUnorderedMap) {
  const std::uint64_t max_id = GetParam();
  std::mt19937_64 rng(42 + max_id);
  std::uniform_int_distribution<std::uint64_t> pick(1, max_id);
  std::uniform_int_distribution<int> op(0, 99);
  IdIndex index;
  std::unordered_map<std::uint64_t, std::size_t> ref;
  for (int step = 0; step < 60000; ++step) {
    const std::uint64_t id = pick(rng);
    const int o = op(rng);
    if (o < 40) {
      const auto [value, inserted] = index.try_emplace(id, static_cast<std::size_t>(step));
      const auto [it, ref_inserted] = ref.try_emplace(id, static_cast<std::size_t>(step));
      ASSERT_EQ(inserted, ref_inserted);
      ASSERT_EQ(value, it->second);
    } else if (o < 55) {
      index.insert_or_assign(id, static_cast<std::size_t>(step));
      ref[id] = static_cast<std::size_t>(step);
    } else if (o < 90) {
      ASSERT_EQ(index.erase(id), ref.erase(id) == 1);
    } else if (o < 99) {
      const std::size_t* v = index.find(id);
      const auto it = ref.find(id);
      ASSERT_EQ(v != nullptr, it != ref.end());
      if (v != nullptr) {
        ASSERT_EQ(*v, it->second);
      }
    } else if (step % 7 == 0) {
      index.clear();
      ref.clear();
    }
    if (step % 5000 == 0) check_same(index, ref, max_id, rng);
  }
  check_same(index, ref, max_id, rng);
}

// 100 ids: a small, crowded table; 5000: growth; 1e12: sparse ids.
INSTANTIATE_TEST_SUITE_P(Ranges, IdIndexRandom, ::testing::Values(100u, 5000u, 1000000000000u));

TEST(IdIndex, SequentialIdsAndClearKeepWorking) {
  IdIndex index;
  for (int round = 0; round < 3; ++round) {
    for (std::uint64_t id = 1; id <= 3000; ++id) index.insert_or_assign(id, id * 10 + round);
    EXPECT_EQ(index.size(), 3000u);
    for (std::uint64_t id = 1; id <= 3000; ++id) ASSERT_EQ(*index.find(id), id * 10 + round);
    EXPECT_EQ(index.find(3001), nullptr);
    index.clear();
    EXPECT_TRUE(index.empty());
    EXPECT_EQ(index.find(5), nullptr);
  }
}

TEST(IdIndex, KeyZeroIsRefused) {
  IdIndex index;
  EXPECT_THROW(index.try_emplace(0, 1), std::invalid_argument);
  EXPECT_EQ(index.find(0), nullptr);
  EXPECT_FALSE(index.erase(0));
  index.insert_or_assign(7, 3);  // with entries (and empty slots) the answer is the same
  EXPECT_EQ(index.find(0), nullptr);
  EXPECT_FALSE(index.erase(0));
  EXPECT_EQ(index.size(), 1u);
  EXPECT_THROW(index.insert_or_assign(0, 1), std::invalid_argument);
}

}  // namespace
}  // namespace sp
