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
#include "browser.hpp"
#include "stillpoint/report/html_report.hpp"
#include "synthetic_run.hpp"

namespace sp::report {
namespace {

TEST(ReportInChromium, PageLoadsCleanlyAndDrawsTheTrajectory) {
  if (!std::filesystem::exists(kChromium)) {
    if (sp::test::on_ci()) FAIL() << kChromium << " not installed on CI (scripts/setup.sh installs it)";
    GTEST_SKIP() << kChromium << " not installed (apt-get install chromium)";
  }
  if (!viewer_assets().available) GTEST_SKIP() << "built without three.js (npm missing at build time)";
  const auto dir = test::make_synthetic_run("chromium", {.poses = 150});
  const auto result = write_report(dir, std::nullopt);
  const BrowserRun run =
      open_in_chromium("file://" + std::filesystem::absolute(result.file).string(), dir.parent_path());
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
  const BrowserRun run =
      open_in_chromium("file://" + std::filesystem::absolute(page).string(), dir.parent_path());
  ASSERT_EQ(run.status, 0) << run.log.substr(0, 4000);
  EXPECT_TRUE(console_errors(run.log).empty());
  EXPECT_EQ(attribute(run.dom, "<html", "data-console-errors"), "0");
  EXPECT_EQ(attribute(run.dom, "id=\"viewer\"", "data-viewer-status"), "unavailable");
}

}  // namespace
}  // namespace sp::report
