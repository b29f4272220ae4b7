// HTML generation from a synthetic run folder: numbers, thumbnails, missing inputs, bad inputs.
#include <gtest/gtest.h>

#include "stillpoint/common/error.hpp"
#include "stillpoint/report/html_report.hpp"
#include "synthetic_run.hpp"

namespace sp::report {
namespace {

using test::make_synthetic_run;
using test::read_file;
using test::write_file;

bool contains(const std::string& s, const std::string& what) { return s.find(what) != std::string::npos; }

// True when an src= or href= attribute points at another host ("http://", "https://", "//").
bool has_external_reference(const std::string& html) {
  for (const std::string attr : {"src=", "href="}) {
    for (std::size_t at = html.find(attr); at != std::string::npos; at = html.find(attr, at + 1)) {
      std::size_t v = at + attr.size();
      if (v < html.size() && (html[v] == '"' || html[v] == '\'')) ++v;
      const std::string value = html.substr(v, 8);
      if (value.starts_with("http:") || value.starts_with("https:") || value.starts_with("//")) return true;
    }
  }
  return false;
}

TEST(Base64, MatchesRfc4648Vectors) {
  EXPECT_EQ(base64(""), "");
  EXPECT_EQ(base64("f"), "Zg==");
  EXPECT_EQ(base64("fo"), "Zm8=");
  EXPECT_EQ(base64("foo"), "Zm9v");
  EXPECT_EQ(base64("foobar"), "Zm9vYmFy");
  EXPECT_EQ(base64(std::string("\xff\xfe\x00", 3)), "//4A");
}

TEST(HtmlEscape, EscapesMarkup) {
  EXPECT_EQ(html_escape("<a href=\"x\">&'"), "&lt;a href=&quot;x&quot;&gt;&amp;&#39;");
}

TEST(Report, SyntheticRunShowsItsNumbers) {
  const auto dir = make_synthetic_run("full");
  const RunData run = load_run(dir);
  ASSERT_TRUE(run.eval.has_value()) << "ground truth from stats.json 'dataset' was not found";
  EXPECT_EQ(run.trajectory.size(), 120u);
  ASSERT_TRUE(run.map_points.has_value());
  EXPECT_EQ(run.map_points->size(), 500u);
  ASSERT_EQ(run.thumbnails.size(), 1u);

  const std::string html = render_report(run, ViewerAssets{});
  // Summary table.
  EXPECT_TRUE(contains(html, "<th>Frames</th><td class=\"num\">123</td>"));
  EXPECT_TRUE(contains(html, "<th>Lost frames</th><td class=\"num\">4</td>"));
  EXPECT_TRUE(contains(html, "<th>Map points</th><td class=\"num\">4567</td>"));
  EXPECT_TRUE(contains(html, "29.5"));
  EXPECT_TRUE(contains(html, "17 / 21"));
  // ATE after SE(3) alignment: only the few-mm wobble is left.
  const std::string ate_row = "<th>ATE RMSE</th><td class=\"num\">";
  const std::size_t at = html.find(ate_row);
  ASSERT_NE(at, std::string::npos);
  const double ate = std::stod(html.substr(at + ate_row.size(), 12));
  EXPECT_GT(ate, 0.0005);
  EXPECT_LT(ate, 0.01);
  EXPECT_NEAR(ate, run.eval->ate.rmse, 1e-4);
  // With the lost frames filled, as the run stored it.
  EXPECT_TRUE(contains(html,
                       "<th>ATE RMSE on every frame (lost frames interpolated)</th><td class=\"num\">0.0123 "
                       "m, max 0.0456 m</td>"));
  // Timing table with median and p95.
  EXPECT_TRUE(contains(html,
                       "<td>extract</td><td class=\"num\">123</td><td class=\"num\">3.25</td><td "
                       "class=\"num\">7.50</td>"));
  EXPECT_TRUE(contains(html, "<td class=\"num\">14.13</td>") ||
              contains(html, "<td class=\"num\">14.12</td>"));
  // Trajectory and error charts are inline SVG with both series.
  EXPECT_TRUE(contains(html, "ground truth</text>"));
  EXPECT_TRUE(contains(html, "estimate (aligned)</text>"));
  EXPECT_TRUE(contains(html, "ATE [m]"));
  // The thumbnail is embedded byte for byte.
  const std::string jpeg = read_file(dir / "culled" / "frame_000010.jpg");
  EXPECT_TRUE(contains(html, "data:image/jpeg;base64," + base64(jpeg)));
  EXPECT_TRUE(contains(html, "37 of 800 features culled"));
  // Built "without three.js" here: the 3-D section says so and no viewer script is emitted.
  EXPECT_TRUE(contains(html, "3-D view unavailable: built without three.js"));
  EXPECT_FALSE(contains(html, "sp-viewer-data"));
  // Self-contained: nothing is loaded from elsewhere.
  EXPECT_FALSE(has_external_reference(html));
}

TEST(Report, ViewerDataIsEmbeddedWhenThreeIsAvailable) {
  const auto dir = make_synthetic_run("viewer");
  ViewerAssets fake;
  fake.available = true;
  fake.three_version = "0.0.0-test";
  fake.three_js_string = "\"three\"";
  fake.orbit_controls_js_string = "\"orbit\"";
  fake.viewer_js = "/* viewer */";
  const std::string html = render_report(load_run(dir), fake);
  EXPECT_TRUE(contains(html, "<script type=\"application/json\" id=\"sp-viewer-data\">"));
  EXPECT_TRUE(contains(html, "window.SP_THREE_SRC = \"three\";"));
  EXPECT_TRUE(contains(html, "<script type=\"module\">\n/* viewer */"));
  EXPECT_TRUE(contains(html, "\"count\":120"));  // the estimate
  EXPECT_TRUE(contains(html, "\"count\":500"));  // the map cloud
  EXPECT_FALSE(contains(html, "3-D view unavailable"));
}

TEST(Report, MissingOptionalInputsBecomeNotes) {
  const auto dir =
      make_synthetic_run("bare", {.groundtruth = false, .map_points = false, .thumbnails = false});
  const RunData run = load_run(dir);
  EXPECT_FALSE(run.eval.has_value());
  EXPECT_FALSE(run.map_points.has_value());
  EXPECT_TRUE(run.thumbnails.empty());
  ViewerAssets fake;
  fake.available = true;
  fake.three_js_string = fake.orbit_controls_js_string = "\"\"";
  const std::string html = render_report(run, fake);
  EXPECT_TRUE(contains(html, "no ground truth"));
  EXPECT_TRUE(contains(html, "n/a (no ground truth)"));
  EXPECT_TRUE(contains(html, "no ground truth: no error to show"));
  EXPECT_TRUE(contains(html, "no thumbnails"));
  EXPECT_TRUE(contains(html, "no map_points.ply"));
  EXPECT_TRUE(contains(html, "<th>Frames</th><td class=\"num\">123</td>"));
}

TEST(Report, BrokenOptionalFilesAreNotedNotFatal) {
  const auto dir = make_synthetic_run("broken_optional");
  write_file(dir / "map_points.ply",
             "ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\n"
             "property float y\nproperty float z\nend_header\nabc");
  write_file(dir / "culled" / "index.json", "{ not json");
  const RunData run = load_run(dir);
  EXPECT_FALSE(run.map_points.has_value());
  EXPECT_EQ(run.thumbnails.size(), 1u);  // found by listing the folder instead
  bool noted_ply = false;
  for (const auto& n : run.notes) noted_ply = noted_ply || contains(n, "map_points.ply");
  EXPECT_TRUE(noted_ply);
}

TEST(Report, BadStatsJsonNamesFileAndLine) {
  const auto dir = make_synthetic_run("bad_stats");
  write_file(dir / "stats.json", "{\n  \"frames\": 12,\n  oops\n}\n");
  try {
    (void)load_run(dir);
    FAIL() << "malformed stats.json accepted";
  } catch (const InputError& e) {
    EXPECT_TRUE(contains(e.what(), (dir / "stats.json").string())) << e.what();
    EXPECT_EQ(e.line(), 3) << e.what();
  }
  write_file(dir / "stats.json", "{\"frames\": \"many\"}");
  EXPECT_THROW((void)load_run(dir), InputError);
  write_file(dir / "stats.json", "[1, 2]");
  EXPECT_THROW((void)load_run(dir), InputError);
  std::filesystem::remove(dir / "stats.json");
  try {
    (void)load_run(dir);
    FAIL() << "missing stats.json accepted";
  } catch (const InputError& e) {
    EXPECT_TRUE(contains(e.what(), "stats.json")) << e.what();
  }
}

TEST(Report, BadTrajectoryNamesFileAndLine) {
  const auto dir = make_synthetic_run("bad_traj");
  write_file(dir / "trajectory.txt", "# comment\n1.0 0 0 0 0 0 0 1\n2.0 0 0 zero 0 0 0 1\n");
  try {
    (void)load_run(dir);
    FAIL() << "malformed trajectory accepted";
  } catch (const InputError& e) {
    EXPECT_TRUE(contains(e.what(), "trajectory.txt")) << e.what();
    EXPECT_EQ(e.line(), 3) << e.what();
  }
  std::filesystem::remove(dir / "trajectory.txt");
  EXPECT_THROW((void)load_run(dir), InputError);
}

TEST(Report, ExplicitGroundTruthMustExist) {
  const auto dir = make_synthetic_run("gt_missing", {.groundtruth = false});
  LoadOptions options;
  options.groundtruth = dir / "nope.txt";
  EXPECT_THROW((void)load_run(dir, options), InputError);
}

TEST(Report, WriteReportWritesOneFile) {
  const auto dir = make_synthetic_run("write");
  const auto result = write_report(dir, std::nullopt);
  EXPECT_EQ(result.file, dir / "report.html");
  ASSERT_TRUE(std::filesystem::exists(result.file));
  EXPECT_EQ(std::filesystem::file_size(result.file), result.bytes);
  const std::string html = read_file(result.file);
  EXPECT_TRUE(contains(html, "</html>"));
  EXPECT_FALSE(has_external_reference(html));
}

}  // namespace
}  // namespace sp::report
