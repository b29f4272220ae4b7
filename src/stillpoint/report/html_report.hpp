#pragma once
// `stillpoint report`: one self-contained HTML page per run (summary, trajectory against ground
// truth, error over time, per-stage timing, culled-feature thumbnails, interactive 3-D view). Every
// image, script and datum is inline; the page makes no request at view time.
#include <filesystem>
#include <optional>
#include <string>

#include "stillpoint/report/run_data.hpp"
#include "stillpoint/report/viewer_assets.hpp"

namespace sp::report {

// The page for a loaded run. `assets` carries three.js (viewer_assets() in the program; tests pass
// their own to check the fallback).
std::string render_report(const RunData& run, const ViewerAssets& assets);

struct ReportResult {
  std::filesystem::path file;
  std::size_t bytes = 0;
  double ms = 0;  // load + render + write
};

// Loads RUN_DIR, renders and writes `out` (default RUN_DIR/report.html) through a temporary file.
ReportResult write_report(const std::filesystem::path& run_dir,
                          const std::optional<std::filesystem::path>& out, const LoadOptions& options = {});

// RFC 4648 base64 (exposed for tests).
std::string base64(std::string_view bytes);
// Escapes &, <, >, " and ' for HTML text and attribute values.
std::string html_escape(std::string_view text);

}  // namespace sp::report
