#include <gtest/gtest.h>

#include <thread>

#include "stillpoint/common/bounded_queue.hpp"

namespace sp {
namespace {

TEST(BoundedQueue, FifoOrderAndCloseDrains) {
  BoundedQueue<int> q(4);
  EXPECT_TRUE(q.push(1));
  EXPECT_TRUE(q.push(2));
  q.close();
  EXPECT_FALSE(q.push(3));
  EXPECT_EQ(q.pop(), 1);
  EXPECT_EQ(q.pop(), 2);
  EXPECT_FALSE(q.pop().has_value());
}

TEST(BoundedQueue, DropOldestKeepsNewest) {
  BoundedQueue<int> q(2);
  EXPECT_FALSE(q.push_drop_oldest(1));
  EXPECT_FALSE(q.push_drop_oldest(2));
  EXPECT_TRUE(q.push_drop_oldest(3));
  EXPECT_EQ(q.try_pop(), 2);
  EXPECT_EQ(q.try_pop(), 3);
  EXPECT_FALSE(q.try_pop().has_value());
}

TEST(BoundedQueue, ProducerBlocksUntilConsumerTakes) {
  BoundedQueue<int> q(1);
  constexpr int kItems = 1000;
  long long sum = 0;
  std::thread consumer([&] {
    while (auto v = q.pop()) sum += *v;
  });
  for (int i = 1; i <= kItems; ++i) ASSERT_TRUE(q.push(i));
  q.close();
  consumer.join();
  EXPECT_EQ(sum, static_cast<long long>(kItems) * (kItems + 1) / 2);
}

TEST(BoundedQueue, PopForTimesOut) {
  BoundedQueue<int> q(1);
  EXPECT_FALSE(q.pop_for(std::chrono::milliseconds(5)).has_value());
}

TEST(BoundedQueue, CloseWakesBlockedProducer) {
  BoundedQueue<int> q(1);
  ASSERT_TRUE(q.push(1));
  bool result = true;
  std::thread producer([&] { result = q.push(2); });
  std::this_thread::sleep_for(std::chrono::milliseconds(10));
  q.close();
  producer.join();
  EXPECT_FALSE(result);
}

}  // namespace
}  // namespace sp
