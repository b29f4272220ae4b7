#pragma once
// Trajectory accuracy with the definitions of the TUM RGB-D benchmark tools: absolute trajectory error
// (evaluate_ate.py) and relative pose error with a fixed delta (evaluate_rpe.py --fixed_delta).
#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "stillpoint/common/config_reader.hpp"
#include "stillpoint/eval/stats.hpp"
#include "stillpoint/geometry/alignment.hpp"
#include "stillpoint/io/trajectory_io.hpp"

namespace sp::eval {

enum class Alignment { SE3, Sim3, None };
enum class DeltaUnit { Seconds, Frames };

struct EvalOptions {
  Alignment align = Alignment::SE3;  // how the estimate is aligned to the ground truth for ATE
  double delta = 1.0;                // RPE step, in delta_unit (> 0)
  DeltaUnit delta_unit = DeltaUnit::Seconds;
  double max_difference = 0.02;  // s, ATE association window
  double offset = 0;             // s, added to estimate stamps

  // Keys: align (se3|sim3|none), delta (0, 1e6], delta_unit (s|f), max_difference [1e-6, 10] s,
  // offset [-1e4, 1e4] s.
  static EvalOptions from_yaml(const ConfigReader& r);
};

struct EvalResult {
  std::size_t pairs = 0;  // associated (gt, est) pairs used for ATE
  ErrorStats ate, rpe_trans, rpe_rot_deg;
  std::size_t rpe_pairs = 0;
  geo::Similarity3 alignment;  // gt ≈ alignment.apply(est)
  // ATE RMSE of each component of the error in the ground-truth camera's frame (x right, y down, z
  // along the optical axis): which direction the error lies in, e.g. depth-axis jitter of a still
  // camera. The three squared add up to ate.rmse squared.
  Eigen::Vector3d ate_camera_axes_rmse = Eigen::Vector3d::Zero();

  // Per associated pair, in time order (for plots).
  std::vector<double> stamps;                                // estimate stamps
  std::vector<Eigen::Vector3d> gt_positions, est_positions;  // estimate positions after alignment
  std::vector<double> ate_errors;                            // metres
  // Per RPE pair (first estimate stamp of the pair).
  std::vector<double> rpe_stamps, rpe_trans_errors, rpe_rot_errors_deg;
};

// With Alignment::Sim3 the estimate's relative motions are scaled by the fitted scale for RPE too
// (evaluate_rpe.py --scale); otherwise RPE compares them as they are.
// Throws sp::Error when the trajectories do not overlap in time (no associated pair, or too few for
// the alignment: 3 for SE3/Sim3). RPE statistics are empty (count 0) when no pair fits the delta.
EvalResult evaluate(const std::vector<io::StampedPose>& gt, const std::vector<io::StampedPose>& est,
                    const EvalOptions& options);

// {"pairs", "ate", "rpe_trans", "rpe_rot_deg", "rpe_pairs", "alignment"}; each stats object has
// rmse, mean, median, std, min, max (and count).
nlohmann::json to_json(const EvalResult& result);
// A readable text table of the figures.
std::string format_table(const EvalResult& result);

// Draws a top view of the ground truth and the aligned estimate with error segments, and the errors over
// time below it (OpenCV only). Throws sp::Error when the file cannot be written.
void write_plot(const std::filesystem::path& png, const EvalResult& result);

}  // namespace sp::eval
