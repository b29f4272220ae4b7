// stillpoint eval: ATE / RPE of an estimated trajectory against ground truth (TUM definitions).
#include <spdlog/spdlog.h>

#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>

#include "commands.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/eval/evaluate.hpp"
#include "stillpoint/io/trajectory_io.hpp"

namespace sp::app {

namespace {

struct EvalArgs {
  std::string gt, est, json, plot;
  double delta = 1.0;
  std::string delta_unit = "s";
  std::string align = "se3";
  double max_difference = 0.02;
  double offset = 0.0;
};

void run_eval(const EvalArgs& a) {
  eval::EvalOptions o;
  o.delta = a.delta;
  o.delta_unit = a.delta_unit == "f" ? eval::DeltaUnit::Frames : eval::DeltaUnit::Seconds;
  o.align = a.align == "sim3"   ? eval::Alignment::Sim3
            : a.align == "none" ? eval::Alignment::None
                                : eval::Alignment::SE3;
  o.max_difference = a.max_difference;
  o.offset = a.offset;
  // A sequence folder stands for its groundtruth.txt.
  std::filesystem::path gt_file = a.gt;
  if (std::filesystem::is_directory(gt_file)) gt_file /= "groundtruth.txt";
  const auto gt = io::read_tum_trajectory(gt_file);
  const auto est = io::read_tum_trajectory(a.est);
  const eval::EvalResult r = eval::evaluate(gt, est, o);
  std::cout << eval::format_table(r) << std::flush;
  if (!a.json.empty()) {
    std::ofstream out(a.json);
    if (!out) throw InputError(a.json, 0, "cannot open for writing");
    out << eval::to_json(r).dump(2) << "\n";
    spdlog::info("wrote {}", a.json);
  }
  if (!a.plot.empty()) {
    eval::write_plot(a.plot, r);
    spdlog::info("wrote {}", a.plot);
  }
}

}  // namespace

void add_eval_command(CLI::App& app) {
  auto args = std::make_shared<EvalArgs>();
  CLI::App* cmd =
      app.add_subcommand("eval", "ATE / RPE of an estimated trajectory against ground truth (TUM)");
  cmd->add_option("--gt", args->gt, "ground-truth trajectory (TUM format), or a sequence folder")
      ->required()
      ->check(CLI::ExistingPath);
  cmd->add_option("--est", args->est, "estimated trajectory (TUM format)")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("--delta", args->delta, "RPE step")->capture_default_str()->check(CLI::PositiveNumber);
  cmd->add_option("--delta-unit", args->delta_unit, "RPE step unit: s (seconds) or f (frames)")
      ->capture_default_str()
      ->check(CLI::IsMember({"s", "f"}));
  cmd->add_option("--align", args->align, "alignment for ATE: se3, sim3 or none")
      ->capture_default_str()
      ->check(CLI::IsMember({"se3", "sim3", "none"}));
  cmd->add_option("--max-difference", args->max_difference, "association window for ATE, seconds")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  cmd->add_option("--offset", args->offset, "time offset added to estimate stamps, seconds")
      ->capture_default_str();
  cmd->add_option("--json", args->json, "write the figures as JSON");
  cmd->add_option("--plot", args->plot, "write a PNG plot (top view and errors over time)");
  cmd->callback([args] { run_eval(*args); });
}

}  // namespace sp::app
