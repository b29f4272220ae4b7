#pragma once
// A pipeline stage: one job, one input queue, one thread. In deterministic mode the owner calls
// process() itself in lock-step instead of starting the thread.
#include <spdlog/spdlog.h>

#include <atomic>
#include <functional>
#include <mutex>
#include <string>
#include <thread>

#include "stillpoint/common/bounded_queue.hpp"
#include "stillpoint/common/thread_priority.hpp"

namespace sp::pipeline {

template <typename In>
class ThreadedStage {
 public:
  ThreadedStage(std::string name, std::size_t queue_capacity)
      : name_(std::move(name)), input_(queue_capacity) {}
  // Derived stages must call stop() in their own destructor: the thread runs their process().
  virtual ~ThreadedStage() = default;
  ThreadedStage(const ThreadedStage&) = delete;
  ThreadedStage& operator=(const ThreadedStage&) = delete;

  // `niceness` > 0 lowers the thread's scheduling priority (Linux applies it per thread), so the
  // tracking thread wins the CPU when the cores are shared.
  void start(int niceness = 0) {
    if (thread_.joinable()) return;
    thread_ = std::thread([this, niceness] {
      lower_this_thread_priority(niceness, name_);
      spin();
    });
  }
  // Finishes the queued work, then joins. Safe to call twice.
  void stop() {
    input_.close();
    if (thread_.joinable()) thread_.join();
  }
  [[nodiscard]] bool threaded() const { return thread_.joinable(); }

  // Threaded: enqueue (blocks when full). Lock-step: runs the job now.
  void submit(In item) {
    ++pending_;
    if (threaded()) {
      input_.push(std::move(item));
    } else {
      run_one(std::move(item));
    }
  }
  [[nodiscard]] bool idle() const { return pending_.load() == 0; }
  [[nodiscard]] std::size_t queued() const { return input_.size(); }
  [[nodiscard]] const std::string& name() const { return name_; }
  // Set when the stage failed; the pipeline reports it and stops.
  [[nodiscard]] bool failed() const { return failed_.load(); }
  // The first failure, "<stage> stage: <error>"; empty while none.
  [[nodiscard]] std::string failure() const {
    std::lock_guard lock(failure_mutex_);
    return failure_;
  }

 protected:
  virtual void process(In item) = 0;

 private:
  void spin() {
    while (auto item = input_.pop()) run_one(std::move(*item));
  }
  void run_one(In item) {
    try {
      process(std::move(item));
    } catch (const std::exception& e) {
      spdlog::error("{} stage failed: {}", name_, e.what());
      {
        std::lock_guard lock(failure_mutex_);
        if (failure_.empty()) failure_ = name_ + " stage: " + e.what();
      }
      failed_ = true;
    }
    --pending_;
  }

  std::string name_;
  BoundedQueue<In> input_;
  std::thread thread_;
  std::atomic<std::size_t> pending_{0};  // queued + running
  std::atomic<bool> failed_{false};
  mutable std::mutex failure_mutex_;
  std::string failure_;
};

}  // namespace sp::pipeline
