// stillpoint eval: ATE / RPE of an estimated trajectory against ground truth (TUM definitions).
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>

#include "commands.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/eval/evaluate.hpp"
#include "stillpoint/eval/missing_frames.hpp"
#include "stillpoint/io/trajectory_io.hpp"
#include "stillpoint/io/tum_text.hpp"

namespace sp::app {

namespace {

struct EvalArgs {
  std::string gt, est, json, plot;
  std::string fill_missing = "skip";
  std::string frames;  // rgb.txt, or a sequence folder (its rgb.txt)
  std::string maps;    // trajectory_maps.txt of the estimate
  double delta = 1.0;
  std::string delta_unit = "s";
  std::string align = "se3";
  double max_difference = 0.02;
  double offset = 0.0;
};

std::vector<std::uint32_t> read_map_ids(const std::filesystem::path& file) {
  std::vector<std::uint32_t> ids;
  for (const auto& r : io::read_tum_text(file, 2)) {
    double id = 0;
    if (!io::parse_double(r.columns[1], id) || id < 0 || id != std::floor(id)) {
      throw InputError(file, r.line, "map id '" + r.columns[1] + "' is not a non-negative integer");
    }
    ids.push_back(static_cast<std::uint32_t>(id));
  }
  return ids;
}

// Gives the estimate a pose for every frame of the sequence, so that systems which leave lost frames
// out and systems which write a pose for each are scored on the same frames.
std::vector<io::StampedPose> fill_missing(const EvalArgs& a, const std::vector<io::StampedPose>& est) {
  // Default: the rgb.txt beside the ground truth (or in the --gt folder).
  std::filesystem::path frames_file = a.frames;
  if (frames_file.empty()) {
    frames_file = std::filesystem::is_directory(a.gt) ? std::filesystem::path(a.gt)
                                                      : std::filesystem::path(a.gt).parent_path();
  }
  if (std::filesystem::is_directory(frames_file)) frames_file /= "rgb.txt";
  if (!std::filesystem::exists(frames_file)) {
    throw Error("--fill-missing needs the sequence's frame list: " + frames_file.string() +
                " does not exist (give --frames rgb.txt, or --gt a sequence folder)");
  }
  const std::vector<double> stamps = eval::read_frame_stamps(frames_file);
  const std::vector<std::uint32_t> maps =
      a.maps.empty() ? std::vector<std::uint32_t>{} : read_map_ids(a.maps);
  if (!maps.empty() && maps.size() != est.size()) {
    throw InputError(a.maps, 0, fmt::format("{} map ids for {} poses in {}", maps.size(), est.size(), a.est));
  }
  const auto mode = a.fill_missing == "hold" ? eval::MissingFrames::Hold : eval::MissingFrames::Interpolate;
  const eval::FilledTrajectory f = eval::fill_missing_frames(stamps, est, mode, maps);
  std::cout << fmt::format("frames {}: {} estimated, {} held, {} interpolated, {} before the first pose\n",
                           stamps.size(), est.size(), f.held, f.interpolated, f.before_first);
  return f.poses;
}

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
  auto est = io::read_tum_trajectory(a.est);
  if (a.fill_missing != "skip") est = fill_missing(a, est);
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
  cmd->add_option("--fill-missing", args->fill_missing,
                  "frames with no pose (lost): skip them, hold the last pose (as ORB-SLAM3 writes them), or "
                  "interpolate across the gap (held at the end and between maps)")
      ->capture_default_str()
      ->check(CLI::IsMember({"skip", "hold", "interpolate"}));
  cmd->add_option("--frames", args->frames,
                  "the sequence's frame list for --fill-missing: rgb.txt or a sequence folder (default: the "
                  "rgb.txt beside --gt)")
      ->check(CLI::ExistingPath);
  cmd->add_option("--maps", args->maps,
                  "trajectory_maps.txt of the estimate: --fill-missing never interpolates between maps")
      ->check(CLI::ExistingFile);
  cmd->add_option("--json", args->json, "write the figures as JSON");
  cmd->add_option("--plot", args->plot, "write a PNG plot (top view and errors over time)");
  cmd->callback([args] { run_eval(*args); });
}

}  // namespace sp::app
