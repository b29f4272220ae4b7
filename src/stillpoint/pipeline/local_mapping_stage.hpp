#pragma once
#include <atomic>
#include <functional>

#include "stillpoint/common/timing.hpp"
#include "stillpoint/mapping/local_mapper.hpp"
#include "stillpoint/pipeline/threaded_stage.hpp"

namespace sp::pipeline {

// Runs the local mapper on each keyframe from tracking, then hands the keyframe on (loop closing).
class LocalMappingStage final : public ThreadedStage<map::KeyframeId> {
 public:
  using Downstream = std::function<void(map::KeyframeId)>;
  LocalMappingStage(mapping::LocalMapper& mapper, StageTimes& times, Downstream downstream,
                    std::size_t capacity)
      : ThreadedStage("local mapping", capacity),
        mapper_(mapper),
        times_(times),
        downstream_(std::move(downstream)) {}
  ~LocalMappingStage() override { stop(); }

  // A newer keyframe is waiting: cut the running bundle adjustment short (ORB-SLAM does the same).
  void interrupt_ba() { abort_ba_ = true; }
  [[nodiscard]] std::size_t keyframes_processed() const { return processed_.load(); }

 protected:
  void process(map::KeyframeId kf) override {
    abort_ba_ = false;
    Stopwatch watch;
    const auto stats = mapper_.process(kf, &abort_ba_);
    times_.add("local_map", watch.elapsed_ms());
    if (stats.ba_ms > 0) times_.add("ba", stats.ba_ms);
    if (stats.triangulation_ms > 0) times_.add("triangulation", stats.triangulation_ms);
    ++processed_;
    if (downstream_) downstream_(kf);
  }

 private:
  mapping::LocalMapper& mapper_;
  StageTimes& times_;
  Downstream downstream_;
  std::atomic<bool> abort_ba_{false};
  std::atomic<std::size_t> processed_{0};
};

}  // namespace sp::pipeline
