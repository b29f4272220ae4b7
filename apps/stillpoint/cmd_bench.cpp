// stillpoint bench: runs sequences x variants (each run in its own process, so memory and crashes
// are measured per run), then prints one table and writes JSON.
#include <fcntl.h>
#include <fmt/format.h>
#include <spawn.h>
#include <spdlog/spdlog.h>
#include <sys/wait.h>

#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>

#include "commands.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/common/timing.hpp"

extern char** environ;

namespace sp::app {

namespace {

struct Variant {
  std::string name;
  std::vector<std::string> args;
};

struct BenchArgs {
  std::vector<std::string> sequences;
  std::string ablation = "none";
  std::string detector_model;
  std::string config;
  std::string out = "bench_out";
  std::string json;
  bool deterministic = false;
  std::size_t max_frames = 0;
  std::vector<std::string> extra;  // passed to every run
};

std::vector<std::string> default_sequences() {
  const char* env = std::getenv("DYNSYNTH_DATA");
  const std::filesystem::path root =
      env != nullptr ? env : std::filesystem::path(std::getenv("HOME")) / "dynsynth";
  std::vector<std::string> out;
  for (const char* name :
       {"office_a_walking_xyz", "office_a_static_xyz", "office_a_sitting_static", "office_a_loop_walking"}) {
    if (std::filesystem::exists(root / name / "rgb.txt")) out.push_back((root / name).string());
  }
  const auto kitchen = std::filesystem::path(SP_SHARED_DIR) / "data" / "real" / "sevenscenes_redkitchen_dev";
  if (std::filesystem::exists(kitchen / "rgb.txt")) out.push_back(kitchen.string());
  return out;
}

std::vector<Variant> variants_for(const std::string& ablation) {
  if (ablation == "none") return {{"default", {}}};
  if (ablation == "dynamic") {  // the paper's Table V: detector x flow
    return {{"cull:off", {"--dynamic", "off"}},
            {"cull:flow", {"--dynamic", "flow"}},
            {"cull:detector", {"--dynamic", "detector"}},
            {"cull:detector+flow", {"--dynamic", "detector+flow"}},
            {"cull:oracle", {"--dynamic", "oracle"}}};
  }
  if (ablation == "keyframes") {  // culling on/off x adaptive on/off
    std::vector<Variant> v;
    for (const char* cull : {"off", "detector+flow"}) {
      for (const char* policy : {"heuristic", "adaptive"}) {
        v.push_back(
            {fmt::format("cull:{} kf:{}", cull, policy), {"--dynamic", cull, "--keyframe-policy", policy}});
      }
    }
    return v;
  }
  if (ablation == "loop") {
    return {{"loop:off", {"--loop-detector", "off"}},
            {"loop:bow-keyframe", {"--loop-detector", "bow-keyframe"}},
            {"loop:bow-sequence", {"--loop-detector", "bow-sequence"}},
            {"loop:netvlad", {"--loop-detector", "netvlad"}}};
  }
  throw Error("unknown ablation '" + ablation + "' (none|dynamic|keyframes|loop)");
}

int spawn_and_wait(const std::vector<std::string>& argv, const std::filesystem::path& log) {
  std::vector<char*> cargv;
  for (const auto& a : argv) cargv.push_back(const_cast<char*>(a.c_str()));
  cargv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&actions, 1, 2);
  pid_t pid = 0;
  const int rc = posix_spawn(&pid, cargv[0], &actions, nullptr, cargv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (rc != 0) throw Error("cannot start " + argv[0]);
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

double stage(const nlohmann::json& s, const char* name, const char* key) {
  if (!s.contains("stages_ms") || !s["stages_ms"].contains(name)) return 0.0;
  return s["stages_ms"][name].value(key, 0.0);
}

nlohmann::json summarize_row(const std::string& seq, const Variant& v, int rc, const nlohmann::json& s) {
  nlohmann::json row;
  row["sequence"] = seq;
  row["variant"] = v.name;
  row["exit_code"] = rc;
  row["frames"] = s.value("frames", 0);
  row["lost_frames"] = s.value("lost_frames", 0);
  row["keyframes"] = s.value("keyframes", 0);
  row["fps"] = s.value("fps", 0.0);
  row["peak_rss_mib"] = s.value("peak_rss_mib", 0.0);
  if (s.contains("eval")) {
    row["ate"] = s["eval"]["ate"];
    row["rpe_trans"] = s["eval"]["rpe_trans"];
    row["rpe_rot_deg"] = s["eval"]["rpe_rot_deg"];
  }
  nlohmann::json ms;
  for (const char* st :
       {"frame", "load", "extract", "dynamic", "detector", "track", "local_map", "ba", "loop"}) {
    ms[st] = {{"median", stage(s, st, "median_ms")}, {"p95", stage(s, st, "p95_ms")}};
  }
  row["ms"] = ms;
  if (s.contains("culling_score")) row["culling_score"] = s["culling_score"];
  for (const char* k :
       {"loops_detected", "loops_closed", "loops_true", "loops_false", "loop_candidates",
        "loop_detection_ms_total", "loop_queries", "loop_bow_ms_total", "loop_global_descriptor_ms_total",
        "vocabulary_words", "vocabulary_load_ms", "keyframes_created", "dynamic_mode", "loop_detector"}) {
    if (s.contains(k)) row[k] = s[k];
  }
  return row;
}

void print_table(const nlohmann::json& rows) {
  fmt::print(
      "\n{:<28} {:<24} {:>5} {:>4} {:>4} | {:>7} {:>7} {:>7} | {:>7} {:>6} | {:>6} {:>6} {:>6} {:>6} {:>6} "
      "{:>6} | {:>6} {:>7} | {:>5} {:>5}\n",
      "sequence", "variant", "frames", "lost", "KFs", "ATE", "mean", "median", "RPE-t", "RPE-r", "frame",
      "p95", "extr", "dyn", "track", "map", "FPS", "RSS MiB", "cullP", "cullR");
  fmt::print(
      "{:<28} {:<24} {:>5} {:>4} {:>4} | {:>7} {:>7} {:>7} | {:>7} {:>6} | {:>6} {:>6} {:>6} {:>6} {:>6} "
      "{:>6} | {:>6} {:>7} | {:>5} {:>5}\n",
      "", "", "", "", "", "cm", "cm", "cm", "cm", "deg", "ms", "ms", "ms", "ms", "ms", "ms", "", "", "", "");
  for (const auto& r : rows) {
    const bool has_eval = r.contains("ate");
    auto cm = [&](const char* key, const char* stat) {
      return has_eval ? fmt::format("{:.2f}", r[key].value(stat, 0.0) * 100.0) : std::string("-");
    };
    const auto& ms = r["ms"];
    auto med = [&](const char* st) { return ms[st].value("median", 0.0); };
    std::string cull_p = "-", cull_r = "-";
    if (r.contains("culling_score") && r["culling_score"].value("true_dynamic_keypoints", 0) > 0) {
      cull_p = fmt::format("{:.2f}", r["culling_score"].value("precision", 0.0));
      cull_r = fmt::format("{:.2f}", r["culling_score"].value("recall", 0.0));
    }
    fmt::print(
        "{:<28} {:<24} {:>5} {:>4} {:>4} | {:>7} {:>7} {:>7} | {:>7} {:>6} | {:>6.1f} {:>6.1f} {:>6.1f} "
        "{:>6.1f} {:>6.1f} {:>6.1f} | {:>6.1f} {:>7.0f} | {:>5} {:>5}{}\n",
        r.value("sequence", ""), r.value("variant", ""), r.value("frames", 0), r.value("lost_frames", 0),
        r.value("keyframes", 0), cm("ate", "rmse"), cm("ate", "mean"), cm("ate", "median"),
        cm("rpe_trans", "rmse"),
        has_eval ? fmt::format("{:.2f}", r["rpe_rot_deg"].value("rmse", 0.0)) : std::string("-"),
        med("frame"), ms["frame"].value("p95", 0.0), med("extract"), med("dynamic"), med("track"),
        med("local_map"), r.value("fps", 0.0), r.value("peak_rss_mib", 0.0), cull_p, cull_r,
        r.value("exit_code", 0) == 0 ? "" : fmt::format("  (exit {})", r.value("exit_code", 0)));
  }
  fmt::print(
      "\nATE/RPE as the TUM benchmark defines them (SE(3) alignment, RPE delta 1 s). ms = median per frame "
      "of\n"
      "the tracking thread (frame) and its steps; map = local mapping per keyframe (own thread).\n");
}

// Loop closing (the paper's Table VIII and more): per run, what the detector cost and what it closed,
// each closed loop judged by ground truth (false = relative pose off by > 10 cm or 5 degrees).
void print_loop_table(const nlohmann::json& rows) {
  bool any = false;
  for (const auto& r : rows) any = any || r.contains("loops_closed");
  if (!any) return;
  fmt::print("\n{:<28} {:<20} | {:>6} {:>5} {:>5} | {:>6} {:>7} {:>9} {:>9} | {:>7} {:>7} | {:>7}\n",
             "sequence", "loop detector", "closed", "true", "false", "cand.", "queries", "detect ms",
             "descr. ms", "vocab", "load ms", "ATE cm");
  for (const auto& r : rows) {
    if (!r.contains("loops_closed")) {
      fmt::print("{:<28} {:<20} | {:>6} {:>5} {:>5} | {:>6} {:>7} {:>9} {:>9} | {:>7} {:>7} | {:>7}\n",
                 r.value("sequence", ""), r.value("variant", ""), "-", "-", "-", "-", "-", "-", "-", "-", "-",
                 r.contains("ate") ? fmt::format("{:.2f}", r["ate"].value("rmse", 0.0) * 100.0) : "-");
      continue;
    }
    const double descr = r.value("loop_bow_ms_total", 0.0) + r.value("loop_global_descriptor_ms_total", 0.0);
    const auto count = [&](const char* k) {
      return r.contains(k) ? fmt::format("{}", r.value(k, 0)) : std::string("-");
    };
    fmt::print("{:<28} {:<20} | {:>6} {:>5} {:>5} | {:>6} {:>7} {:>9.1f} {:>9.1f} | {:>7} {:>7.1f} | {:>7}\n",
               r.value("sequence", ""), r.value("variant", ""), r.value("loops_closed", 0),
               count("loops_true"), count("loops_false"), r.value("loop_candidates", 0),
               r.value("loop_queries", 0), r.value("loop_detection_ms_total", 0.0), descr,
               r.value("vocabulary_words", 0), r.value("vocabulary_load_ms", 0.0),
               r.contains("ate") ? fmt::format("{:.2f}", r["ate"].value("rmse", 0.0) * 100.0) : "-");
  }
  fmt::print(
      "detect ms = database search in total (not descriptors, not verification); descr. ms = BoW or "
      "ParC_NetVLAD\ndescriptors of all keyframes; vocab = words of the loaded vocabulary and its load "
      "time.\n");
}

void bench(const BenchArgs& args) {
  const std::vector<std::string> sequences = args.sequences.empty() ? default_sequences() : args.sequences;
  if (sequences.empty())
    throw Error("no sequences: pass --sequences DIR... or render the dev set into $DYNSYNTH_DATA");
  std::string model = args.detector_model;
  const auto shared_model = std::filesystem::path(SP_SHARED_DIR) / "models" / "yolox_nano.onnx";
  if (model.empty() && std::filesystem::exists(shared_model)) model = shared_model.string();
  const std::string self = std::filesystem::read_symlink("/proc/self/exe").string();
  nlohmann::json rows = nlohmann::json::array();
  for (const auto& seq : sequences) {
    const std::string seq_name = std::filesystem::path(seq).filename().string();
    for (const auto& v : variants_for(args.ablation)) {
      std::string dir_name = v.name;
      for (char& c : dir_name) {
        if (c == ':' || c == ' ' || c == '+') c = '_';
      }
      const auto out = std::filesystem::path(args.out) / seq_name / dir_name;
      std::filesystem::create_directories(out);
      std::vector<std::string> argv{self, "run", "--dataset", seq, "--out", out.string(), "--no-progress"};
      if (!model.empty()) argv.insert(argv.end(), {"--detector-model", model});
      if (!args.config.empty()) argv.insert(argv.end(), {"--config", args.config});
      if (args.deterministic) argv.emplace_back("--deterministic");
      if (args.max_frames > 0) argv.insert(argv.end(), {"--max-frames", std::to_string(args.max_frames)});
      argv.insert(argv.end(), v.args.begin(), v.args.end());
      argv.insert(argv.end(), args.extra.begin(), args.extra.end());
      spdlog::info("bench: {} [{}]", seq_name, v.name);
      const int rc = spawn_and_wait(argv, out / "log.txt");
      nlohmann::json stats;
      if (std::ifstream in(out / "stats.json"); in) stats = nlohmann::json::parse(in, nullptr, false);
      if (stats.is_discarded()) stats = nlohmann::json::object();
      rows.push_back(summarize_row(seq_name, v, rc, stats));
      if (rc != 0) spdlog::warn("run failed (exit {}), see {}", rc, (out / "log.txt").string());
    }
  }
  print_table(rows);
  print_loop_table(rows);
  const std::string json_file =
      args.json.empty() ? (std::filesystem::path(args.out) / "bench.json").string() : args.json;
  std::ofstream(json_file) << nlohmann::json{{"runs", rows}}.dump(2) << "\n";
  fmt::print("JSON: {}\n", json_file);
}

}  // namespace

void add_bench_command(CLI::App& app) {
  auto args = std::make_shared<BenchArgs>();
  CLI::App* cmd = app.add_subcommand(
      "bench", "Benchmark: sequences x variants -> one table (ATE/RPE, ms per stage, memory) + JSON");
  cmd->add_option("--sequences", args->sequences,
                  "Sequence folders (default: the dev set in $DYNSYNTH_DATA + the real kitchen)");
  cmd->add_option("--ablation", args->ablation, "none|dynamic (Table V)|keyframes (culling x adaptive)|loop")
      ->capture_default_str();
  cmd->add_option("--detector-model", args->detector_model,
                  "YOLO model (default: ../shared/models/yolox_nano.onnx if present)");
  cmd->add_option("--config", args->config, "System configuration YAML");
  cmd->add_option("--out", args->out, "Folder for the runs' outputs")->capture_default_str();
  cmd->add_option("--json", args->json, "JSON file (default: OUT/bench.json)");
  cmd->add_flag("--deterministic", args->deterministic,
                "Run every sequence in deterministic (lock-step) mode");
  cmd->add_option("--max-frames", args->max_frames, "Frames per sequence (0 = all)");
  cmd->add_option("--run-args", args->extra,
                  "Extra arguments for every run (e.g. --run-args=--loop-detector --run-args=off)");
  cmd->callback([args] { bench(*args); });
}

}  // namespace sp::app
