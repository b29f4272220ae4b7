#pragma once
#include <algorithm>
#include <atomic>
#include <functional>
#include <mutex>

#include "stillpoint/common/timing.hpp"
#include "stillpoint/mapping/local_mapper.hpp"
#include "stillpoint/pipeline/threaded_stage.hpp"

namespace sp::pipeline {

// What local BA did over a run: how often it was solved or dropped and how far it carried keyframes.
// Large moves of keyframes already tracked are the signature of a poorly constrained window
// (docs/tracking_precision.md), so they are counted per threshold.
struct LocalBASummary {
  std::size_t solved = 0;
  std::size_t aborted = 0;
  std::size_t dropped = 0;
  std::size_t held_keyframes = 0;  // weakly constrained keyframes held at their poses
  double largest_keyframe_move_m = 0;
  std::size_t moves_over_1cm = 0;
  std::size_t moves_over_3cm = 0;
  std::size_t moves_over_10cm = 0;

  void add(const mapping::LocalMappingStats& s) {
    if (s.ba_aborted) ++aborted;
    if (s.ba_dropped) ++dropped;
    held_keyframes += static_cast<std::size_t>(s.ba_held_keyframes);
    if (!s.ba_solved) return;
    ++solved;
    largest_keyframe_move_m = std::max(largest_keyframe_move_m, s.ba_largest_keyframe_move_m);
    if (s.ba_largest_keyframe_move_m > 0.01) ++moves_over_1cm;
    if (s.ba_largest_keyframe_move_m > 0.03) ++moves_over_3cm;
    if (s.ba_largest_keyframe_move_m > 0.10) ++moves_over_10cm;
  }
};

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
  [[nodiscard]] LocalBASummary ba_summary() const {
    const std::lock_guard lock(summary_mutex_);
    return ba_summary_;
  }

 protected:
  void process(map::KeyframeId kf) override {
    abort_ba_ = false;
    Stopwatch watch;
    const auto stats = mapper_.process(kf, &abort_ba_);
    times_.add("local_map", watch.elapsed_ms());
    if (stats.ba_ms > 0) times_.add("ba", stats.ba_ms);
    if (stats.triangulation_ms > 0) times_.add("triangulation", stats.triangulation_ms);
    {
      const std::lock_guard lock(summary_mutex_);
      ba_summary_.add(stats);
    }
    ++processed_;
    if (downstream_) downstream_(kf);
  }

 private:
  mapping::LocalMapper& mapper_;
  StageTimes& times_;
  Downstream downstream_;
  std::atomic<bool> abort_ba_{false};
  std::atomic<std::size_t> processed_{0};
  mutable std::mutex summary_mutex_;
  LocalBASummary ba_summary_;
};

}  // namespace sp::pipeline
