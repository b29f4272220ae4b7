// Text and JSON summaries of an evaluation.
#include <fmt/format.h>

#include "stillpoint/eval/evaluate.hpp"

namespace sp::eval {

namespace {

nlohmann::json stats_json(const ErrorStats& s) {
  return {{"rmse", s.rmse}, {"mean", s.mean}, {"median", s.median}, {"std", s.std},
          {"min", s.min},   {"max", s.max},   {"count", s.count}};
}

std::string row(const std::string& name, const std::string& unit, const ErrorStats& s, double k) {
  return fmt::format("{:<14}{:>6}{:>11.5f}{:>11.5f}{:>11.5f}{:>11.5f}{:>11.5f}{:>11.5f}\n", name, unit,
                     s.rmse * k, s.mean * k, s.median * k, s.std * k, s.min * k, s.max * k);
}

}  // namespace

nlohmann::json to_json(const EvalResult& r) {
  nlohmann::json j;
  j["pairs"] = r.pairs;
  j["ate"] = stats_json(r.ate);
  j["rpe_trans"] = stats_json(r.rpe_trans);
  j["rpe_rot_deg"] = stats_json(r.rpe_rot_deg);
  j["rpe_pairs"] = r.rpe_pairs;
  const Eigen::Vector3d& axes = r.ate_camera_axes_rmse;
  j["ate_camera_axes_rmse"] = {{"x_right", axes.x()}, {"y_down", axes.y()}, {"z_optical_axis", axes.z()}};
  const Eigen::Matrix3d& R = r.alignment.R;
  j["alignment"] = {
      {"scale", r.alignment.scale},
      {"t", {r.alignment.t.x(), r.alignment.t.y(), r.alignment.t.z()}},
      {"R", {{R(0, 0), R(0, 1), R(0, 2)}, {R(1, 0), R(1, 1), R(1, 2)}, {R(2, 0), R(2, 1), R(2, 2)}}}};
  return j;
}

std::string format_table(const EvalResult& r) {
  std::string out = fmt::format("{:<14}{:>6}{:>11}{:>11}{:>11}{:>11}{:>11}{:>11}\n", "metric", "unit", "rmse",
                                "mean", "median", "std", "min", "max");
  out += row("ATE", "m", r.ate, 1.0);
  out += row("RPE trans", "m", r.rpe_trans, 1.0);
  out += row("RPE rot", "deg", r.rpe_rot_deg, 1.0);
  out += fmt::format("ATE pairs {}, RPE pairs {}", r.pairs, r.rpe_pairs);
  if (r.alignment.scale != 1.0) out += fmt::format(", Sim(3) scale {:.5f}", r.alignment.scale);
  out += "\n";
  const Eigen::Vector3d& axes = r.ate_camera_axes_rmse;
  out += fmt::format(
      "ATE rmse in the camera's frame (m): x right {:.5f}, y down {:.5f}, z optical axis {:.5f}\n", axes.x(),
      axes.y(), axes.z());
  return out;
}

}  // namespace sp::eval
