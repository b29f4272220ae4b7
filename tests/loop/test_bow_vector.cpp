#include <gtest/gtest.h>

#include "stillpoint/common/error.hpp"
#include "stillpoint/loop/bow_vector.hpp"

namespace sp::loop {
namespace {

TEST(BowVector, FromEntriesSortsAndMerges) {
  const BowVector v = BowVector::from_entries({{5, 1.0}, {2, 0.5}, {5, 2.0}});
  ASSERT_EQ(v.size(), 2U);
  EXPECT_EQ(v.entries()[0].first, 2U);
  EXPECT_DOUBLE_EQ(v.weight(5), 3.0);
  EXPECT_DOUBLE_EQ(v.weight(7), 0.0);
  EXPECT_THROW(BowVector::from_entries({{1, -1.0}}), sp::Error);
}

TEST(BowVector, L1ScoreMatchesDefinition) {
  BowVector a = BowVector::from_entries({{1, 2.0}, {2, 2.0}});
  BowVector b = BowVector::from_entries({{2, 1.0}, {3, 3.0}});
  // a/|a| = (.5,.5,0), b/|b| = (0,.25,.75): 1 - 0.5 * (.5 + .25 + .75) = 0.25
  EXPECT_NEAR(l1_score(a, b), 0.25, 1e-12);
  EXPECT_NEAR(l1_score(a, a), 1.0, 1e-12);
  EXPECT_NEAR(l1_score(a, BowVector()), 0.0, 1e-12);
  EXPECT_EQ(common_words(a, b), 1U);
}

TEST(BowVector, NormalizedSumWeighsInputsEqually) {
  const BowVector a = BowVector::from_entries({{1, 10.0}});
  const BowVector b = BowVector::from_entries({{2, 1.0}, {3, 1.0}});
  const BowVector s = normalized_sum({&a, &b});
  EXPECT_NEAR(s.l1_norm(), 1.0, 1e-12);
  EXPECT_NEAR(s.weight(1), 0.5, 1e-12);
  EXPECT_NEAR(s.weight(2), 0.25, 1e-12);
  EXPECT_NEAR(s.weight(3), 0.25, 1e-12);
}

}  // namespace
}  // namespace sp::loop
