#pragma once
#include "stillpoint/common/timing.hpp"
#include "stillpoint/loop/loop_closer.hpp"
#include "stillpoint/pipeline/threaded_stage.hpp"

namespace sp::pipeline {

// Runs loop detection and correction on each keyframe that local mapping has finished.
class LoopClosingStage final : public ThreadedStage<map::KeyframeId> {
 public:
  LoopClosingStage(loop::LoopCloser& closer, StageTimes& times, std::size_t capacity)
      : ThreadedStage("loop closing", capacity), closer_(closer), times_(times) {}
  ~LoopClosingStage() override { stop(); }

 protected:
  void process(map::KeyframeId kf) override {
    Stopwatch watch;
    closer_.process(kf);
    times_.add("loop", watch.elapsed_ms());
  }

 private:
  loop::LoopCloser& closer_;
  StageTimes& times_;
};

}  // namespace sp::pipeline
