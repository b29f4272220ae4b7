// The report page in headless Chromium: it loads with no console error and the 3-D view draws the
// estimated trajectory (viewer.js renders it alone once and counts the pixels it covered).
// Skipped when /usr/bin/chromium is missing (a failure on CI, environment variable CI set: CI installs
// it with scripts/setup.sh) or when this build has no three.js (npm or the registry missing at build
// time).
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <fstream>

#include "../support/shared_data.hpp"
#include "stillpoint/report/html_report.hpp"
#include "synthetic_run.hpp"

namespace sp::report {
namespace {

constexpr const char* kChromium = "/usr/bin/chromium";

struct BrowserRun {
  int status = -1;
  std::string dom;  // --dump-dom output
  std::string log;  // Chromium's log, console messages included
};

std::string shell_quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

BrowserRun open_in_chromium(const std::filesystem::path& page, const std::filesystem::path& scratch) {
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
      shell_quote("file://" + std::filesystem::absolute(page).string()) + " 2>" + shell_quote(log.string());
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
std::string attribute(const std::string& dom, const std::string& marker, const std::string& attr) {
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
std::vector<std::string> console_errors(const std::string& log) {
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

TEST(ReportInChromium, PageLoadsCleanlyAndDrawsTheTrajectory) {
  if (!std::filesystem::exists(kChromium)) {
    if (sp::test::on_ci()) FAIL() << kChromium << " not installed on CI (scripts/setup.sh installs it)";
    GTEST_SKIP() << kChromium << " not installed (apt-get install chromium)";
  }
  if (!viewer_assets().available) GTEST_SKIP() << "built without three.js (npm missing at build time)";
  const auto dir = test::make_synthetic_run("chromium", {.poses = 150});
  const auto result = write_report(dir, std::nullopt);
  const BrowserRun run = open_in_chromium(result.file, dir.parent_path());
  ASSERT_EQ(run.status, 0) << "chromium failed:\n" << run.log.substr(0, 4000);
  ASSERT_NE(run.dom.find("</html>"), std::string::npos) << "no DOM dumped:\n" << run.log.substr(0, 4000);

  const auto errors = console_errors(run.log);
  std::string joined;
  for (const auto& e : errors) joined += e + "\n";
  EXPECT_TRUE(errors.empty()) << joined;
  EXPECT_EQ(attribute(run.dom, "<html", "data-console-errors"), "0")
      << attribute(run.dom, "<html", "data-console-error-first");

  const std::string viewer = "id=\"viewer\"";
  EXPECT_EQ(attribute(run.dom, viewer, "data-viewer-status"), "ok")
      << "viewer error: " << attribute(run.dom, viewer, "data-viewer-error");
  EXPECT_EQ(attribute(run.dom, viewer, "data-trajectory-points"), "150");
  const std::string pixels = attribute(run.dom, viewer, "data-trajectory-pixels");
  ASSERT_FALSE(pixels.empty());
  EXPECT_GT(std::stol(pixels), 100) << "the trajectory line covered almost no pixel";
}

TEST(ReportInChromium, PageWithoutThreeSaysSoWithoutErrors) {
  if (!std::filesystem::exists(kChromium)) {
    if (sp::test::on_ci()) FAIL() << kChromium << " not installed on CI (scripts/setup.sh installs it)";
    GTEST_SKIP() << kChromium << " not installed (apt-get install chromium)";
  }
  const auto dir = test::make_synthetic_run("chromium_fallback", {.groundtruth = false, .map_points = false});
  const auto page = dir / "fallback.html";
  std::ofstream(page) << render_report(load_run(dir), ViewerAssets{});
  const BrowserRun run = open_in_chromium(page, dir.parent_path());
  ASSERT_EQ(run.status, 0) << run.log.substr(0, 4000);
  EXPECT_TRUE(console_errors(run.log).empty());
  EXPECT_EQ(attribute(run.dom, "<html", "data-console-errors"), "0");
  EXPECT_EQ(attribute(run.dom, "id=\"viewer\"", "data-viewer-status"), "unavailable");
}

}  // namespace
}  // namespace sp::report
