#pragma once
// stillpoint bench, suite mode: the pure aggregation of single runs into one row per (sequence, variant)
// (medians over repeats) and a per-variant summary over the sequences (overall and per group, the first
// path component of the sequence name, e.g. "tune" or "heldout"). No I/O, so it is unit-tested.
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

namespace sp::app::bench {

// One run of one variant on one sequence. A metric is empty when the run did not produce it (failed
// run, no ground truth, no culling masks, ...).
struct RunMetrics {
  std::string sequence;
  std::string variant;
  int repeat = 0;
  int exit_code = 0;
  std::optional<double> ate_cm;        // ATE RMSE after SE(3) alignment
  std::optional<double> max_error_cm;  // max per-frame translation error after alignment (ATE max)
  // ATE RMSE with every frame given a pose (lost ones interpolated across their gap, the rule of
  // `eval --fill-missing interpolate`): like for like with systems that write a pose for each frame.
  std::optional<double> ate_every_frame_cm;
  std::optional<double> lost_frames;
  std::optional<double> fps;
  std::optional<double> track_ms;  // tracking thread, median ms per frame
  std::optional<double> lock_ms;   // ... of which it held the map lock, median ms per frame
  std::optional<double> cull_precision, cull_recall;
};

// Medians over the repeats of one (sequence, variant); spread = min..max of the repeats' ATE.
struct AggregateRow {
  std::string sequence;
  std::string variant;
  int runs = 0;    // repeats run
  int failed = 0;  // repeats with a non-zero exit code
  std::optional<double> ate_cm, ate_min_cm, ate_max_cm, ate_every_frame_cm;
  std::optional<double> max_error_cm, lost_frames, fps, track_ms, lock_ms, cull_precision, cull_recall;
};

// One variant over the sequences of one group ("all" = every sequence).
struct SummaryRow {
  std::string group;
  std::string variant;
  int sequences = 0;                                  // sequences this variant ran on
  int with_ate = 0;                                   // ... of which have an ATE
  int failed_runs = 0;                                // runs with a non-zero exit code
  std::optional<double> ate_median_cm, ate_worst_cm;  // over the sequences' medians
  std::optional<double> max_error_worst_cm;
  double lost_frames_total = 0;  // sum over sequences of the median lost frames
  std::optional<double> fps_median;
  // ATE / ATE of the oracle variant on the same sequence (sequences where both have an ATE > 0).
  int oracle_pairs = 0;
  std::optional<double> oracle_ratio_median, oracle_ratio_worst;
};

// numpy's median (mean of the two middle values for an even count); empty for no values.
std::optional<double> median(std::vector<double> values);

// The run metrics of one bench row (the JSON of a run as `bench` writes it: "ate" {rmse, max} in metres,
// "every_frame" {ate_rmse_m},
// lost_frames, fps, ms.frame.median, ms.track_lock.median, culling_score {precision, recall,
// true_dynamic_keypoints}).
RunMetrics metrics_from_row(const nlohmann::json& row);

// True for the variant culling with ground-truth masks: named "oracle" (or ending in ":oracle"), or
// whose run arguments contain "--dynamic oracle" / "--dynamic=oracle".
bool is_oracle_variant(const std::string& name, const std::vector<std::string>& args);

// The group of a sequence: the first component of its path relative to the suite ("tune/room101_x" ->
// "tune"); empty for a sequence at the top level.
std::string sequence_group(const std::string& sequence);

// One row per (sequence, variant), in the order they first appear in `runs`.
std::vector<AggregateRow> aggregate_repeats(const std::vector<RunMetrics>& runs);

// Per variant: the group "all" over every sequence, then one group per first path component (only when
// some sequence has one). `oracle` names the oracle variant (empty: no oracle ratio). Variants keep the
// order of their first appearance.
std::vector<SummaryRow> summarize(const std::vector<AggregateRow>& rows, const std::string& oracle);

nlohmann::json to_json(const RunMetrics& m);
nlohmann::json to_json(const AggregateRow& r);
nlohmann::json to_json(const SummaryRow& r);

// A peer's speed from its logs (run.sh's output and the example's own): like for like with ours
// (frames / wall of the frame loop and the final drain) where the example prints "loop wall ... with
// shutdown: B s" (the measurement edit of scripts/speed_vs_ngd.sh); else run.sh's "wall=Ws" of the
// whole binary, vocabulary loading included; else `fallback_wall_s`.
struct PeerSpeed {
  double wall_s = 0;
  double fps = 0;
  bool frame_loop = false;         // wall_s is the frame loop's (comparable with ours)
  std::optional<double> track_ms;  // the example's "median tracking time", ms
};
PeerSpeed peer_speed(const std::string& log, std::size_t frames, double fallback_wall_s);

}  // namespace sp::app::bench
