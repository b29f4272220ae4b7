#include "stillpoint/common/timing.hpp"

#include <fstream>
#include <sstream>
#include <thread>

namespace sp {

namespace {

// The value of one "Key:   123 kB" line of /proc/self/status in MiB, 0 when absent (not Linux).
double proc_status_mib(const std::string& key) {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line)) {
    if (line.rfind(key, 0) == 0) {
      std::istringstream in(line.substr(key.size()));
      double kib = 0;
      in >> kib;
      return kib / 1024.0;
    }
  }
  return 0.0;
}

}  // namespace

double peak_rss_mib() { return proc_status_mib("VmHWM:"); }

double current_rss_mib() { return proc_status_mib("VmRSS:"); }

void PlaybackClock::wait_for(double stamp) {
  const auto wait = due_in(stamp, Clock::now());
  if (wait > Clock::duration::zero()) std::this_thread::sleep_for(wait);
}

}  // namespace sp
