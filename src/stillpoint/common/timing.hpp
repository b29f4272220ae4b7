#pragma once
// Wall-clock measurement for statistics and benchmarks (never for test assertions).
#include <algorithm>
#include <chrono>
#include <map>
#include <mutex>
#include <string>
#include <vector>

namespace sp {

class Stopwatch {
 public:
  Stopwatch() : start_(Clock::now()) {}
  void restart() { start_ = Clock::now(); }
  [[nodiscard]] double elapsed_ms() const {
    return std::chrono::duration<double, std::milli>(Clock::now() - start_).count();
  }

 private:
  using Clock = std::chrono::steady_clock;
  Clock::time_point start_;
};

struct SampleSummary {
  std::size_t count = 0;
  double total = 0, mean = 0, median = 0, p95 = 0, max = 0;
};

inline SampleSummary summarize(std::vector<double> samples) {
  SampleSummary s;
  s.count = samples.size();
  if (samples.empty()) return s;
  std::sort(samples.begin(), samples.end());
  for (double v : samples) s.total += v;
  s.mean = s.total / static_cast<double>(samples.size());
  const auto at = [&](double q) {
    const double pos = q * static_cast<double>(samples.size() - 1);
    const auto lo = static_cast<std::size_t>(pos);
    const std::size_t hi = std::min(lo + 1, samples.size() - 1);
    return samples[lo] + (pos - static_cast<double>(lo)) * (samples[hi] - samples[lo]);
  };
  s.median = at(0.5);
  s.p95 = at(0.95);
  s.max = samples.back();
  return s;
}

// Plays frames back at their recorded pace (scaled by `rate`), like the camera that recorded them: the
// first frame anchors the clock, a later one is due at anchor + (stamp - first stamp) / rate. Frames
// that are already due are not delayed (and never dropped). rate <= 0: every frame is due at once.
class PlaybackClock {
 public:
  using Clock = std::chrono::steady_clock;
  explicit PlaybackClock(double rate) : rate_(rate) {}

  // How long a frame stamped `stamp` (seconds) still has to wait at `now`.
  [[nodiscard]] Clock::duration due_in(double stamp, Clock::time_point now) {
    if (rate_ <= 0) return Clock::duration::zero();
    if (!anchored_) {
      anchored_ = true;
      first_stamp_ = stamp;
      anchor_ = now;
      return Clock::duration::zero();
    }
    const auto due = anchor_ + std::chrono::duration_cast<Clock::duration>(
                                   std::chrono::duration<double>((stamp - first_stamp_) / rate_));
    return due > now ? due - now : Clock::duration::zero();
  }

  void wait_for(double stamp);  // sleeps for due_in(stamp, now)

 private:
  double rate_;
  bool anchored_ = false;
  double first_stamp_ = 0;
  Clock::time_point anchor_;
};

// Per-stage millisecond samples, written by several threads.
class StageTimes {
 public:
  void add(const std::string& stage, double ms) {
    std::lock_guard lock(mutex_);
    samples_[stage].push_back(ms);
  }
  [[nodiscard]] std::map<std::string, SampleSummary> summaries() const {
    std::lock_guard lock(mutex_);
    std::map<std::string, SampleSummary> out;
    for (const auto& [stage, v] : samples_) out[stage] = summarize(v);
    return out;
  }

 private:
  mutable std::mutex mutex_;
  std::map<std::string, std::vector<double>> samples_;
};

// Peak resident set size of this process in MiB (VmHWM), 0 when unknown.
double peak_rss_mib();

// Current resident set size of this process in MiB (VmRSS), 0 when unknown. Sampled during a run
// to show whether memory stays flat (the peak alone cannot tell growth from one early spike).
double current_rss_mib();

}  // namespace sp
