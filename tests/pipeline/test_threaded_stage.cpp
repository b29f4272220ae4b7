// A pipeline stage whose job throws: the stage records the first failure (stage name and error) for the
// runner's stop reason, keeps working through the items after it, and reports the same in lock-step
// (deterministic) mode, where the owner runs the job itself.
#include <gtest/gtest.h>

#include <stdexcept>
#include <vector>

#include "stillpoint/pipeline/threaded_stage.hpp"

namespace sp::pipeline {
namespace {

class ThrowsOnNegative : public ThreadedStage<int> {
 public:
  ThrowsOnNegative() : ThreadedStage<int>("numbers", 4) {}
  ~ThrowsOnNegative() override { stop(); }
  std::vector<int> done;

 protected:
  void process(int item) override {
    if (item < 0) throw std::runtime_error("negative item " + std::to_string(item));
    done.push_back(item);
  }
};

void feed(ThrowsOnNegative& stage) {
  for (int item : {1, -2, 3, -4, 5}) stage.submit(item);
}

TEST(ThreadedStage, RecordsTheFirstFailureAndKeepsWorkingThreaded) {
  ThrowsOnNegative stage;
  stage.start();
  EXPECT_FALSE(stage.failed());
  EXPECT_TRUE(stage.failure().empty());
  feed(stage);
  stage.stop();  // drains the queue
  EXPECT_TRUE(stage.failed());
  EXPECT_EQ(stage.failure(), "numbers stage: negative item -2");
  EXPECT_EQ(stage.done, (std::vector<int>{1, 3, 5}));
  EXPECT_TRUE(stage.idle());
}

TEST(ThreadedStage, RecordsTheFirstFailureInLockStep) {
  ThrowsOnNegative stage;  // never started: submit() runs the job at once
  stage.submit(1);
  EXPECT_FALSE(stage.failed());
  feed(stage);
  EXPECT_TRUE(stage.failed());
  EXPECT_EQ(stage.failure(), "numbers stage: negative item -2");
  EXPECT_EQ(stage.done, (std::vector<int>{1, 1, 3, 5}));
}

}  // namespace
}  // namespace sp::pipeline
