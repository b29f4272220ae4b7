#pragma once
// A terminal progress bar for long runs; on a non-terminal it prints a line every 10 %.
#include <cstddef>
#include <cstdio>
#include <string>

namespace sp {

class ProgressBar {
 public:
  ProgressBar(std::string label, std::size_t total, bool enabled = true);
  ~ProgressBar();
  ProgressBar(const ProgressBar&) = delete;
  ProgressBar& operator=(const ProgressBar&) = delete;

  // `done` items finished; `note` is shown after the bar (e.g. "fps 31.2").
  void update(std::size_t done, const std::string& note = "");
  void finish();

 private:
  std::string label_;
  std::size_t total_;
  bool enabled_;
  bool tty_;
  bool finished_ = false;
  int last_decile_ = -1;
};

}  // namespace sp
