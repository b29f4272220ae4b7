#include "bench_aggregate.hpp"

#include <algorithm>
#include <map>
#include <regex>
#include <utility>

namespace sp::app::bench {

namespace {

std::optional<double> number_at(const nlohmann::json& j, const char* key) {
  if (!j.is_object() || !j.contains(key) || !j[key].is_number()) return std::nullopt;
  return j[key].get<double>();
}

std::optional<double> scaled(std::optional<double> v, double factor) {
  if (v) *v *= factor;
  return v;
}

// Median over the values the runs have.
template <typename Get>
std::optional<double> median_of(const std::vector<const RunMetrics*>& runs, Get get) {
  std::vector<double> v;
  for (const auto* r : runs) {
    if (const std::optional<double> x = get(*r)) v.push_back(*x);
  }
  return median(std::move(v));
}

std::optional<double> max_of(const std::vector<double>& v) {
  if (v.empty()) return std::nullopt;
  return *std::max_element(v.begin(), v.end());
}

nlohmann::json opt(const std::optional<double>& v) { return v ? nlohmann::json(*v) : nlohmann::json(); }

}  // namespace

std::optional<double> median(std::vector<double> values) {
  if (values.empty()) return std::nullopt;
  std::sort(values.begin(), values.end());
  const std::size_t mid = values.size() / 2;
  return values.size() % 2 == 1 ? values[mid] : 0.5 * (values[mid - 1] + values[mid]);
}

RunMetrics metrics_from_row(const nlohmann::json& row) {
  RunMetrics m;
  m.sequence = row.value("sequence", std::string());
  m.variant = row.value("variant", std::string());
  m.repeat = row.value("repeat", 0);
  m.exit_code = row.value("exit_code", 0);
  if (row.contains("ate")) {
    m.ate_cm = scaled(number_at(row["ate"], "rmse"), 100.0);
    m.max_error_cm = scaled(number_at(row["ate"], "max"), 100.0);
  }
  if (row.contains("every_frame"))
    m.ate_every_frame_cm = scaled(number_at(row["every_frame"], "ate_rmse_m"), 100.0);
  // A run that wrote no stats (crashed) has no frames: its zeros are not measurements.
  if (row.value("frames", 0) > 0) {
    m.lost_frames = number_at(row, "lost_frames");
    m.fps = number_at(row, "fps");
    if (row.contains("ms") && row["ms"].contains("frame")) {
      const auto ms = number_at(row["ms"]["frame"], "median");
      if (ms && *ms > 0) m.track_ms = ms;
    }
    // Runs from before the lock was measured have no track_lock (bench writes 0 for a missing stage).
    if (row.contains("ms") && row["ms"].contains("track_lock")) {
      const auto ms = number_at(row["ms"]["track_lock"], "median");
      if (ms && *ms > 0) m.lock_ms = ms;
    }
  }
  if (row.contains("culling_score") && row["culling_score"].value("true_dynamic_keypoints", 0) > 0) {
    m.cull_precision = number_at(row["culling_score"], "precision");
    m.cull_recall = number_at(row["culling_score"], "recall");
  }
  return m;
}

bool is_oracle_variant(const std::string& name, const std::vector<std::string>& args) {
  const std::string suffix = ":oracle";
  if (name == "oracle" ||
      (name.size() > suffix.size() && name.compare(name.size() - suffix.size(), suffix.size(), suffix) == 0))
    return true;
  for (std::size_t i = 0; i < args.size(); ++i) {
    if (args[i] == "--dynamic=oracle") return true;
    if (args[i] == "--dynamic" && i + 1 < args.size() && args[i + 1] == "oracle") return true;
  }
  return false;
}

std::string sequence_group(const std::string& sequence) {
  const auto slash = sequence.find('/');
  return slash == std::string::npos ? std::string() : sequence.substr(0, slash);
}

std::vector<AggregateRow> aggregate_repeats(const std::vector<RunMetrics>& runs) {
  std::vector<std::pair<std::string, std::string>> order;
  std::map<std::pair<std::string, std::string>, std::vector<const RunMetrics*>> by_key;
  for (const auto& r : runs) {
    auto key = std::make_pair(r.sequence, r.variant);
    auto& list = by_key[key];
    if (list.empty()) order.push_back(key);
    list.push_back(&r);
  }
  std::vector<AggregateRow> out;
  for (const auto& key : order) {
    const auto& list = by_key[key];
    AggregateRow row;
    row.sequence = key.first;
    row.variant = key.second;
    row.runs = static_cast<int>(list.size());
    std::vector<double> ates;
    for (const auto* r : list) {
      if (r->exit_code != 0) ++row.failed;
      if (r->ate_cm) ates.push_back(*r->ate_cm);
    }
    row.ate_cm = median(ates);
    if (!ates.empty()) {
      row.ate_min_cm = *std::min_element(ates.begin(), ates.end());
      row.ate_max_cm = *std::max_element(ates.begin(), ates.end());
    }
    row.max_error_cm = median_of(list, [](const RunMetrics& r) { return r.max_error_cm; });
    row.ate_every_frame_cm = median_of(list, [](const RunMetrics& r) { return r.ate_every_frame_cm; });
    row.lost_frames = median_of(list, [](const RunMetrics& r) { return r.lost_frames; });
    row.fps = median_of(list, [](const RunMetrics& r) { return r.fps; });
    row.track_ms = median_of(list, [](const RunMetrics& r) { return r.track_ms; });
    row.lock_ms = median_of(list, [](const RunMetrics& r) { return r.lock_ms; });
    row.cull_precision = median_of(list, [](const RunMetrics& r) { return r.cull_precision; });
    row.cull_recall = median_of(list, [](const RunMetrics& r) { return r.cull_recall; });
    out.push_back(std::move(row));
  }
  return out;
}

std::vector<SummaryRow> summarize(const std::vector<AggregateRow>& rows, const std::string& oracle) {
  std::vector<std::string> variants;
  std::vector<std::string> groups{"all"};
  bool nested = false;
  std::map<std::string, double> oracle_ate;  // sequence -> the oracle's median ATE
  for (const auto& r : rows) {
    if (std::find(variants.begin(), variants.end(), r.variant) == variants.end())
      variants.push_back(r.variant);
    const std::string g = sequence_group(r.sequence);
    if (!g.empty()) nested = true;
    if (std::find(groups.begin() + 1, groups.end(), g) == groups.end()) groups.push_back(g);
    if (!oracle.empty() && r.variant == oracle && r.ate_cm) oracle_ate[r.sequence] = *r.ate_cm;
  }
  if (!nested) groups.resize(1);
  std::vector<SummaryRow> out;
  for (const auto& g : groups) {
    for (const auto& v : variants) {
      SummaryRow s;
      s.group = g.empty() ? std::string("(top level)") : g;
      s.variant = v;
      std::vector<double> ates, max_errors, fps, ratios;
      for (const auto& r : rows) {
        if (r.variant != v || (g != "all" && sequence_group(r.sequence) != g)) continue;
        ++s.sequences;
        s.failed_runs += r.failed;
        if (r.ate_cm) {
          ++s.with_ate;
          ates.push_back(*r.ate_cm);
          const auto o = oracle_ate.find(r.sequence);
          if (o != oracle_ate.end() && o->second > 0) ratios.push_back(*r.ate_cm / o->second);
        }
        if (r.max_error_cm) max_errors.push_back(*r.max_error_cm);
        if (r.fps) fps.push_back(*r.fps);
        if (r.lost_frames) s.lost_frames_total += *r.lost_frames;
      }
      if (s.sequences == 0) continue;
      s.ate_median_cm = median(ates);
      s.ate_worst_cm = max_of(ates);
      s.max_error_worst_cm = max_of(max_errors);
      s.fps_median = median(fps);
      s.oracle_pairs = static_cast<int>(ratios.size());
      s.oracle_ratio_median = median(ratios);
      s.oracle_ratio_worst = max_of(ratios);
      out.push_back(std::move(s));
    }
  }
  return out;
}

nlohmann::json to_json(const RunMetrics& m) {
  return {{"sequence", m.sequence},
          {"variant", m.variant},
          {"repeat", m.repeat},
          {"exit_code", m.exit_code},
          {"ate_cm", opt(m.ate_cm)},
          {"max_error_cm", opt(m.max_error_cm)},
          {"ate_every_frame_cm", opt(m.ate_every_frame_cm)},
          {"lost_frames", opt(m.lost_frames)},
          {"fps", opt(m.fps)},
          {"track_ms", opt(m.track_ms)},
          {"lock_ms", opt(m.lock_ms)},
          {"cull_precision", opt(m.cull_precision)},
          {"cull_recall", opt(m.cull_recall)}};
}

nlohmann::json to_json(const AggregateRow& r) {
  return {{"sequence", r.sequence},
          {"variant", r.variant},
          {"runs", r.runs},
          {"failed_runs", r.failed},
          {"ate_cm_median", opt(r.ate_cm)},
          {"ate_cm_min", opt(r.ate_min_cm)},
          {"ate_cm_max", opt(r.ate_max_cm)},
          {"max_error_cm_median", opt(r.max_error_cm)},
          {"ate_every_frame_cm_median", opt(r.ate_every_frame_cm)},
          {"lost_frames_median", opt(r.lost_frames)},
          {"fps_median", opt(r.fps)},
          {"track_ms_median", opt(r.track_ms)},
          {"lock_ms_median", opt(r.lock_ms)},
          {"cull_precision_median", opt(r.cull_precision)},
          {"cull_recall_median", opt(r.cull_recall)}};
}

nlohmann::json to_json(const SummaryRow& r) {
  return {{"group", r.group},
          {"variant", r.variant},
          {"sequences", r.sequences},
          {"sequences_with_ate", r.with_ate},
          {"failed_runs", r.failed_runs},
          {"ate_cm_median", opt(r.ate_median_cm)},
          {"ate_cm_worst", opt(r.ate_worst_cm)},
          {"max_error_cm_worst", opt(r.max_error_worst_cm)},
          {"lost_frames_total", r.lost_frames_total},
          {"fps_median", opt(r.fps_median)},
          {"oracle_pairs", r.oracle_pairs},
          {"oracle_ratio_median", opt(r.oracle_ratio_median)},
          {"oracle_ratio_worst", opt(r.oracle_ratio_worst)}};
}

namespace {
// The number of the last match of `re` (its first group) in `text`.
std::optional<double> last_number(const std::string& text, const std::regex& re) {
  std::optional<double> last;
  for (auto it = std::sregex_iterator(text.begin(), text.end(), re); it != std::sregex_iterator(); ++it) {
    try {
      last = std::stod((*it)[1].str());
    } catch (const std::exception&) {
    }
  }
  return last;
}
}  // namespace

PeerSpeed peer_speed(const std::string& log, std::size_t frames, double fallback_wall_s) {
  PeerSpeed p;
  const auto loop_wall = last_number(log, std::regex(R"(with shutdown:\s*([0-9.]+)\s*s)"));
  p.frame_loop = loop_wall.has_value();
  p.wall_s = loop_wall.value_or(last_number(log, std::regex(R"(wall=([0-9.]+)s)")).value_or(fallback_wall_s));
  p.fps = p.wall_s > 0 ? static_cast<double>(frames) / p.wall_s : 0.0;
  if (const auto t = last_number(log, std::regex(R"(median tracking time:\s*([0-9.eE+-]+))")))
    p.track_ms = *t * 1000.0;
  return p;
}

}  // namespace sp::app::bench
