#include "stillpoint/dynamic/async_detector.hpp"

#include <spdlog/spdlog.h>

#include "stillpoint/common/thread_priority.hpp"
#include "stillpoint/dynamic/yolo_detector.hpp"

namespace sp::dyn {

AsyncDetector::AsyncDetector(DetectFn detect, Mode mode, int niceness)
    : detect_(std::move(detect)), mode_(mode) {
  if (mode_ == Mode::kAsync) {
    worker_ = std::thread([this, niceness] {
      lower_this_thread_priority(niceness, "detector");
      run();
    });
  }
}

AsyncDetector::AsyncDetector(const DetectorConfig& cfg, Mode mode, int niceness)
    : AsyncDetector(
          [det = std::make_shared<YoloDetector>(cfg)](const cv::Mat& bgr) { return det->detect(bgr); }, mode,
          niceness) {}

AsyncDetector::~AsyncDetector() { stop(); }

void AsyncDetector::submit(std::size_t frame_index, double stamp, const cv::Mat& bgr) {
  rethrow_worker_error();
  {
    std::lock_guard lock(mutex_);
    if (stopped_) return;
  }
  if (mode_ == Mode::kSync) {
    Detections d = detect_(bgr);
    d.frame_index = frame_index;
    d.stamp = stamp;
    if (sync_latency_ > 0) {
      std::lock_guard lock(mutex_);
      delayed_.push_back(std::move(d));
    } else {
      store(std::move(d));
    }
    return;
  }
  if (queue_.push_drop_oldest(Job{frame_index, stamp, bgr.clone()})) {
    std::lock_guard lock(mutex_);
    ++dropped_;
  }
}

std::optional<Detections> AsyncDetector::latest() const {
  std::lock_guard lock(mutex_);
  return latest_;
}

std::optional<Detections> AsyncDetector::wait_for(std::size_t frame_index, std::chrono::milliseconds budget) {
  rethrow_worker_error();
  if (mode_ == Mode::kSync) {
    // Nothing runs in the background to wait for: what is finished (and due) is all there is. Delayed
    // results are in submission order, each newer than latest_.
    std::lock_guard lock(mutex_);
    while (!delayed_.empty() && delayed_.front().frame_index + sync_latency_ <= frame_index) {
      latest_ = std::move(delayed_.front());
      delayed_.pop_front();
    }
    return latest_;
  }
  std::optional<Detections> result;
  {
    std::unique_lock lock(mutex_);
    done_.wait_for(lock, budget,
                   [&] { return stopped_ || error_ || (latest_ && latest_->frame_index >= frame_index); });
    result = latest_;
  }
  rethrow_worker_error();  // a failure that woke the wait reaches the caller now, not one call later
  return result;
}

AsyncDetector::Fresh AsyncDetector::wait_for_fresh(std::size_t frame_index, std::chrono::milliseconds budget,
                                                   std::size_t max_age, std::chrono::milliseconds stale_wait,
                                                   bool wait_first) {
  Fresh out;
  out.detections = wait_for(frame_index, budget);
  if (max_age == 0) return out;
  if (out.detections && out.detections->frame_index + max_age >= frame_index) return out;
  // In the first max_age frames only "no detection at all" is stale.
  if (frame_index <= max_age && !wait_first) return out;
  const auto t0 = std::chrono::steady_clock::now();
  out.detections = wait_for(frame_index > max_age ? frame_index - max_age : 0, stale_wait);
  out.stale_wait_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return out;
}

void AsyncDetector::stop() {
  {
    std::lock_guard lock(mutex_);
    stopped_ = true;
  }
  queue_.close();
  while (queue_.try_pop()) {
  }
  if (worker_.joinable()) worker_.join();
  done_.notify_all();
}

void AsyncDetector::set_sync_latency(std::size_t frames) {
  std::lock_guard lock(mutex_);
  sync_latency_ = frames;
}

std::size_t AsyncDetector::dropped() const {
  std::lock_guard lock(mutex_);
  return dropped_;
}

void AsyncDetector::run() {
  while (auto job = queue_.pop()) {
    try {
      Detections d = detect_(job->image);
      d.frame_index = job->frame_index;
      d.stamp = job->stamp;
      store(std::move(d));
    } catch (...) {
      spdlog::error("detector thread: detection of frame {} failed", job->frame_index);
      std::lock_guard lock(mutex_);
      error_ = std::current_exception();
      done_.notify_all();
    }
  }
}

void AsyncDetector::store(Detections d) {
  std::lock_guard lock(mutex_);
  // Results arrive in submission order; never let an older one replace a newer one.
  if (!latest_ || d.frame_index >= latest_->frame_index) latest_ = std::move(d);
  done_.notify_all();
}

void AsyncDetector::rethrow_worker_error() {
  std::exception_ptr e;
  {
    std::lock_guard lock(mutex_);
    e = std::exchange(error_, nullptr);
  }
  if (e) std::rethrow_exception(e);
}

}  // namespace sp::dyn
