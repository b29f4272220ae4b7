#pragma once
// Lower priority for a helper thread (detector, local mapping, loop closing), so that the tracking
// thread wins the CPU when the cores are shared.
#include <spdlog/spdlog.h>
#include <sys/resource.h>
#include <unistd.h>

#include <string_view>

namespace sp {

// Applies `niceness` (> 0) to the calling thread only: Linux keeps a nice value per thread (tid), not
// per process. Logs a warning naming `thread` when the system refuses.
inline void lower_this_thread_priority(int niceness, std::string_view thread) {
  if (niceness > 0 && setpriority(PRIO_PROCESS, static_cast<id_t>(::gettid()), niceness) != 0)
    spdlog::warn("{} thread: could not lower its priority", thread);
}

}  // namespace sp
