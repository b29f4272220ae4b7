#pragma once
// Headless Chromium for the page tests (report.html, the live view): open a URL, dump the DOM after
// the page's virtual time budget, read attributes and console errors.
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

namespace sp::report {

inline constexpr const char* kChromium = "/usr/bin/chromium";

struct BrowserRun {
  int status = -1;
  std::string dom;  // --dump-dom output
  std::string log;  // Chromium's log, console messages included
};

inline std::string shell_quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

inline BrowserRun open_in_chromium(const std::string& url, const std::filesystem::path& scratch) {
  const auto profile = scratch / "profile";
  std::filesystem::remove_all(profile);
  std::filesystem::create_directories(profile);
  const auto log = scratch / "chromium.log";
  // --disable-gpu keeps the GPU process off real hardware; WebGL then runs on SwiftShader, which
  // Chromium only allows with --enable-unsafe-swiftshader (without it, it logs a deprecation error).
  const std::string command =
      std::string("timeout 120 ") + kChromium +
      " --headless --no-sandbox --disable-gpu --disable-quic --no-first-run --disable-background-networking"
      " --disable-component-update --disable-sync --use-angle=swiftshader --enable-unsafe-swiftshader"
      " --user-data-dir=" +
      shell_quote(profile.string()) +
      " --window-size=1280,2000 --enable-logging=stderr --v=0 --virtual-time-budget=20000 --dump-dom " +
      shell_quote(url) + " 2>" + shell_quote(log.string());
  BrowserRun run;
  FILE* pipe = popen(command.c_str(), "r");
  if (pipe == nullptr) return run;
  char buf[65536];
  std::size_t n = 0;
  while ((n = fread(buf, 1, sizeof buf, pipe)) > 0) run.dom.append(buf, n);
  run.status = pclose(pipe);
  std::ifstream in(log);
  run.log.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  return run;
}

// Value of `attr="..."` on the element whose opening tag contains `marker`.
inline std::string attribute(const std::string& dom, const std::string& marker, const std::string& attr) {
  const std::size_t el = dom.find(marker);
  if (el == std::string::npos) return "";
  const std::size_t tag_start = dom.rfind('<', el);
  const std::size_t tag_end = dom.find('>', el);
  const std::string tag = dom.substr(tag_start, tag_end - tag_start);
  const std::size_t at = tag.find(" " + attr + "=\"");
  if (at == std::string::npos) return "";
  const std::size_t v = at + attr.size() + 3;
  return tag.substr(v, tag.find('"', v) - v);
}

// Console lines Chromium logs that are errors: uncaught exceptions, blocked or failed loads.
inline std::vector<std::string> console_errors(const std::string& log) {
  std::vector<std::string> errors;
  std::size_t start = 0;
  while (start < log.size()) {
    std::size_t end = log.find('\n', start);
    if (end == std::string::npos) end = log.size();
    const std::string line = log.substr(start, end - start);
    start = end + 1;
    if (line.find(":CONSOLE") == std::string::npos) continue;
    for (const char* bad : {"Uncaught", "Refused to", "Failed to load", "net::ERR",
                            "THREE.WebGLRenderer:", "deprecated", "Error"})
      if (line.find(bad) != std::string::npos) {
        errors.push_back(line);
        break;
      }
  }
  return errors;
}

}  // namespace sp::report
