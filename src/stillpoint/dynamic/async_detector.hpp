#pragma once
// Runs a detector in its own thread on the newest submitted frame, so tracking never waits for
// the network longer than it chooses to (wait_for's budget).
#include <chrono>
#include <condition_variable>
#include <deque>
#include <exception>
#include <functional>
#include <memory>
#include <mutex>
#include <opencv2/core.hpp>
#include <optional>
#include <thread>

#include "stillpoint/common/bounded_queue.hpp"
#include "stillpoint/dynamic/detection.hpp"

namespace sp::dyn {

class AsyncDetector {
 public:
  using DetectFn = std::function<Detections(const cv::Mat& bgr)>;
  enum class Mode { kAsync, kSync };  // kSync: submit() detects in the caller's thread (deterministic)

  // Wraps any detection function (tests, other detectors); frame_index/stamp are filled in here.
  // `niceness` (0-19) lowers the worker thread's scheduling priority: on a 2-core robot board the
  // tracking thread should win the CPU, the detector's boxes are carried forward by flow anyway.
  AsyncDetector(DetectFn detect, Mode mode, int niceness = 0);
  // Builds a YoloDetector in the caller's thread (load errors throw here, not in the worker).
  AsyncDetector(const DetectorConfig& cfg, Mode mode, int niceness = 0);
  ~AsyncDetector();
  AsyncDetector(const AsyncDetector&) = delete;
  AsyncDetector& operator=(const AsyncDetector&) = delete;

  // Never blocks in kAsync mode: the image is copied and, when the worker is busy, replaces any
  // frame still waiting (only the newest is kept). Ignored after stop(). Rethrows a detector error
  // raised in the worker.
  void submit(std::size_t frame_index, double stamp, const cv::Mat& bgr);

  // The most recent finished detection (of any frame), if any.
  [[nodiscard]] std::optional<Detections> latest() const;

  // Waits at most `budget` until the detection of `frame_index` (or a newer frame) is done, then
  // returns the latest available one (possibly older; nullopt if none finished yet). A detector
  // failure, before or during the wait, is rethrown here (once).
  std::optional<Detections> wait_for(std::size_t frame_index, std::chrono::milliseconds budget);

  // wait_for(frame_index, budget); then, when the result is more than `max_age` frames older than
  // frame_index (or none exists), waits up to `stale_wait` more for one at most that old: boxes too
  // stale to carry by flow miss people who entered the view since. max_age 0: no second wait.
  // `wait_first`: in the first max_age frames, when no detection has finished yet, wait up to
  // `stale_wait` for the first one (false: those frames go on without boxes).
  struct Fresh {
    std::optional<Detections> detections;
    double stale_wait_ms = 0;  // time spent in the second wait
  };
  Fresh wait_for_fresh(std::size_t frame_index, std::chrono::milliseconds budget, std::size_t max_age,
                       std::chrono::milliseconds stale_wait, bool wait_first = false);

  // Finishes the frame in progress (cv::dnn cannot be interrupted), drops pending ones and joins.
  // Idempotent; the destructor calls it.
  void stop();

  // kSync only: a detection of frame i becomes visible from frame i + frames on (wait_for* with that
  // frame index), as if the network had taken that long: deterministic runs that see boxes as late as
  // a threaded run on a busy CPU does. 0 (default): at once.
  void set_sync_latency(std::size_t frames);

  // Frames submitted but replaced before the worker took them.
  [[nodiscard]] std::size_t dropped() const;

 private:
  struct Job {
    std::size_t frame_index = 0;
    double stamp = 0;
    cv::Mat image;
  };
  void run();
  void store(Detections d);
  void rethrow_worker_error();

  DetectFn detect_;
  Mode mode_;
  BoundedQueue<Job> queue_{1};
  mutable std::mutex mutex_;
  std::condition_variable done_;
  std::optional<Detections> latest_;
  std::exception_ptr error_;
  std::size_t dropped_ = 0;
  bool stopped_ = false;
  std::size_t sync_latency_ = 0;
  std::deque<Detections> delayed_;  // kSync with latency: finished, not visible yet (submission order)
  std::thread worker_;
};

}  // namespace sp::dyn
