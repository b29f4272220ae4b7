#include "stillpoint/common/progress_bar.hpp"

#include <unistd.h>

#include <algorithm>

namespace sp {

ProgressBar::ProgressBar(std::string label, std::size_t total, bool enabled)
    : label_(std::move(label)),
      total_(std::max<std::size_t>(total, 1)),
      enabled_(enabled),
      tty_(isatty(fileno(stderr)) != 0) {}

ProgressBar::~ProgressBar() { finish(); }

void ProgressBar::update(std::size_t done, const std::string& note) {
  if (!enabled_ || finished_) return;
  const double frac = std::min(1.0, static_cast<double>(done) / static_cast<double>(total_));
  if (tty_) {
    constexpr int kWidth = 30;
    const int filled = static_cast<int>(frac * kWidth);
    std::string bar(static_cast<std::size_t>(filled), '#');
    bar.resize(kWidth, '.');
    std::fprintf(stderr, "\r%s [%s] %5.1f%% %zu/%zu %s\x1b[K", label_.c_str(), bar.c_str(), frac * 100.0,
                 done, total_, note.c_str());
    std::fflush(stderr);
  } else {
    const int decile = static_cast<int>(frac * 10.0);
    if (decile != last_decile_) {
      last_decile_ = decile;
      std::fprintf(stderr, "%s %3d%% %zu/%zu %s\n", label_.c_str(), decile * 10, done, total_, note.c_str());
    }
  }
}

void ProgressBar::finish() {
  if (!enabled_ || finished_) return;
  finished_ = true;
  if (tty_) std::fprintf(stderr, "\n");
}

}  // namespace sp
