#pragma once
// Lower priority for a helper thread (detector, local mapping, loop closing), so that the tracking
// thread wins the CPU when the cores are shared.
#include <spdlog/spdlog.h>
#include <sys/resource.h>
#include <unistd.h>

#include <cerrno>
#include <string_view>

namespace sp {

// Applies `niceness` (> 0, absolute) to the calling thread only: Linux keeps a nice value per thread
// (tid), not per process. A thread already at that niceness or lower priority (the whole process run
// under `nice`) keeps its own. Logs a warning naming `thread` when the system refuses.
inline void lower_this_thread_priority(int niceness, std::string_view thread) {
  if (niceness <= 0) return;
  const auto tid = static_cast<id_t>(::gettid());
  errno = 0;
  const int current = getpriority(PRIO_PROCESS, tid);
  if (errno == 0 && current >= niceness) return;
  if (setpriority(PRIO_PROCESS, tid, niceness) != 0)
    spdlog::warn("{} thread: could not lower its priority", thread);
}

}  // namespace sp
