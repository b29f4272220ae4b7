// stillpoint report: one self-contained HTML page for a run folder (see docs/report.md).
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "commands.hpp"
#include "stillpoint/report/html_report.hpp"

namespace sp::app {

namespace {

struct ReportArgs {
  std::string run_dir;
  std::string out;
  std::string groundtruth;
};

void report(const ReportArgs& args) {
  report::LoadOptions options;
  if (!args.groundtruth.empty()) options.groundtruth = args.groundtruth;
  std::optional<std::filesystem::path> out;
  if (!args.out.empty()) out = args.out;
  const auto result = report::write_report(args.run_dir, out, options);
  fmt::print("report: {} ({:.1f} MB, {:.0f} ms){}\n", result.file.string(),
             static_cast<double>(result.bytes) / 1e6, result.ms,
             report::viewer_assets().available ? "" : " [3-D view unavailable: built without three.js]");
}

}  // namespace

void add_report_command(CLI::App& app) {
  auto args = std::make_shared<ReportArgs>();
  CLI::App* cmd = app.add_subcommand(
      "report", "Write RUN_DIR/report.html: summary, trajectory, errors, timing, culled frames, 3-D view");
  cmd->add_option("run_dir", args->run_dir, "Output folder of `stillpoint run`")->required();
  cmd->add_option("--out", args->out, "HTML file to write (default: RUN_DIR/report.html)");
  cmd->add_option("--groundtruth", args->groundtruth,
                  "Ground truth, TUM format (default: groundtruth.txt of the run's sequence, when present)");
  cmd->callback([args] { report(*args); });
}

}  // namespace sp::app
