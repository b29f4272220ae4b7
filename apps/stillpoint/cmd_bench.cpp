// stillpoint bench: runs sequences x variants x repeats (each run in its own process, so memory and
// crashes are measured per run), then prints the tables and writes JSON. Suite mode (--suite DIR) runs
// every sequence folder under DIR and reports medians over repeats, a per-variant summary per group of
// sequences (first path component, e.g. tune / heldout) and optional peers (ORB-SLAM2, NGD-SLAM).
#include <fcntl.h>
#include <fmt/format.h>
#include <spawn.h>
#include <spdlog/spdlog.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <sstream>

#include "bench_aggregate.hpp"
#include "commands.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/common/timing.hpp"
#include "stillpoint/eval/evaluate.hpp"
#include "stillpoint/eval/missing_frames.hpp"
#include "stillpoint/io/trajectory_io.hpp"

extern char** environ;

namespace sp::app {

namespace {

struct Variant {
  std::string name;
  std::vector<std::string> args;
};

struct BenchArgs {
  std::vector<std::string> sequences;
  std::string suite;
  int repeats = 1;
  std::vector<std::string> variant_specs;  // "name=run args"
  std::vector<std::string> peers;
  std::string peer_pace = "flat";  // flat: peers as fast as they can, like our runs | recorded: 30 Hz
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
            {"loop:netvlad", {"--loop-detector", "netvlad"}},
            {"loop:hybrid", {"--loop-detector", "hybrid"}}};
  }
  throw Error("unknown ablation '" + ablation + "' (none|dynamic|keyframes|loop)");
}

// `env_set`: NAME=VALUE entries that replace or add to this process's environment in the child.
int spawn_and_wait(const std::vector<std::string>& argv, const std::filesystem::path& log,
                   const std::vector<std::string>& env_set = {}) {
  std::vector<char*> cargv;
  for (const auto& a : argv) cargv.push_back(const_cast<char*>(a.c_str()));
  cargv.push_back(nullptr);
  std::vector<std::string> env_strings;
  for (char** e = environ; *e != nullptr; ++e) {
    const std::string entry(*e);
    const std::string name = entry.substr(0, entry.find('='));
    const bool replaced = std::any_of(env_set.begin(), env_set.end(), [&](const std::string& set) {
      return set.compare(0, name.size() + 1, name + "=") == 0;
    });
    if (!replaced) env_strings.push_back(entry);
  }
  env_strings.insert(env_strings.end(), env_set.begin(), env_set.end());
  std::vector<char*> cenv;
  for (auto& e : env_strings) cenv.push_back(e.data());
  cenv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&actions, 1, 2);
  pid_t pid = 0;
  const int rc = posix_spawn(&pid, cargv[0], &actions, nullptr, cargv.data(), cenv.data());
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
  if (s.contains("every_frame")) row["every_frame"] = s["every_frame"];
  nlohmann::json ms;
  for (const char* st : {"frame", "load", "extract", "dynamic", "detector", "track", "track_lock",
                         "track_lock_wait", "local_map", "ba", "loop"}) {
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
      "\n{:<28} {:<24} {:>5} {:>4} {:>4} | {:>7} {:>7} {:>7} {:>7} | {:>7} {:>6} | {:>6} {:>6} {:>6} {:>6} "
      "{:>6} {:>6} {:>6} {:>6} | {:>6} {:>7} | {:>5} {:>5}\n",
      "sequence", "variant", "frames", "lost", "KFs", "ATE", "mean", "median", "ATE all", "RPE-t", "RPE-r",
      "frame", "p95", "extr", "dyn", "track", "lock", "lock95", "map", "FPS", "RSS MiB", "cullP", "cullR");
  fmt::print(
      "{:<28} {:<24} {:>5} {:>4} {:>4} | {:>7} {:>7} {:>7} {:>7} | {:>7} {:>6} | {:>6} {:>6} {:>6} {:>6} "
      "{:>6} {:>6} {:>6} {:>6} | {:>6} {:>7} | {:>5} {:>5}\n",
      "", "", "", "", "", "cm", "cm", "cm", "cm", "cm", "deg", "ms", "ms", "ms", "ms", "ms", "ms", "ms", "ms",
      "", "", "", "");
  for (const auto& r : rows) {
    const bool has_eval = r.contains("ate");
    auto cm = [&](const char* key, const char* stat) {
      return has_eval ? fmt::format("{:.2f}", r[key].value(stat, 0.0) * 100.0) : std::string("-");
    };
    const std::string ate_all = r.contains("every_frame") && r["every_frame"].contains("ate_rmse_m")
                                    ? fmt::format("{:.2f}", r["every_frame"].value("ate_rmse_m", 0.0) * 100.0)
                                    : std::string("-");
    const auto& ms = r["ms"];
    auto med = [&](const char* st) { return ms[st].value("median", 0.0); };
    std::string cull_p = "-", cull_r = "-";
    if (r.contains("culling_score") && r["culling_score"].value("true_dynamic_keypoints", 0) > 0) {
      cull_p = fmt::format("{:.2f}", r["culling_score"].value("precision", 0.0));
      cull_r = fmt::format("{:.2f}", r["culling_score"].value("recall", 0.0));
    }
    fmt::print(
        "{:<28} {:<24} {:>5} {:>4} {:>4} | {:>7} {:>7} {:>7} {:>7} | {:>7} {:>6} | {:>6.1f} {:>6.1f} "
        "{:>6.1f} "
        "{:>6.1f} {:>6.1f} {:>6.2f} {:>6.2f} {:>6.1f} | {:>6.1f} {:>7.0f} | {:>5} {:>5}{}\n",
        r.value("sequence", ""), r.value("variant", ""), r.value("frames", 0), r.value("lost_frames", 0),
        r.value("keyframes", 0), cm("ate", "rmse"), cm("ate", "mean"), cm("ate", "median"), ate_all,
        cm("rpe_trans", "rmse"),
        has_eval ? fmt::format("{:.2f}", r["rpe_rot_deg"].value("rmse", 0.0)) : std::string("-"),
        med("frame"), ms["frame"].value("p95", 0.0), med("extract"), med("dynamic"), med("track"),
        med("track_lock"), ms["track_lock"].value("p95", 0.0), med("local_map"), r.value("fps", 0.0),
        r.value("peak_rss_mib", 0.0), cull_p, cull_r,
        r.value("exit_code", 0) == 0 ? "" : fmt::format("  (exit {})", r.value("exit_code", 0)));
  }
  fmt::print(
      "\nATE/RPE as the TUM benchmark defines them (SE(3) alignment, RPE delta 1 s); ATE all = ATE with lost "
      "frames\ninterpolated (trajectory_every_frame.txt). ms = median per frame of\n"
      "the tracking thread (frame) and its steps; lock/lock95 = median/p95 per frame of the time tracking\n"
      "held the map lock; map = local mapping per keyframe (own thread).\n");
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

// A sequence to run: its folder and its name in the tables (path relative to the suite).
struct Sequence {
  std::filesystem::path dir;
  std::string name;
};

// Every folder under `root` with an rgb.txt (not looking inside a sequence), sorted by relative path.
std::vector<Sequence> discover_suite(const std::filesystem::path& root) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::is_directory(root, ec)) throw Error("--suite " + root.string() + ": no such folder");
  std::vector<Sequence> out;
  if (fs::exists(root / "rgb.txt")) return {{root, fs::canonical(root).filename().string()}};
  for (auto it = fs::recursive_directory_iterator(root, fs::directory_options::skip_permission_denied, ec);
       !ec && it != fs::recursive_directory_iterator(); it.increment(ec)) {
    std::error_code entry_ec;  // a broken link is skipped, not an error
    if (!it->is_directory(entry_ec)) continue;
    if (fs::exists(it->path() / "rgb.txt")) {
      out.push_back(
          {it->path(),
           it->path().lexically_normal().lexically_relative(root.lexically_normal()).generic_string()});
      it.disable_recursion_pending();  // rgb/, depth/, masks/ of a sequence hold no sequences
    }
  }
  if (ec) throw Error("--suite " + root.string() + ": " + ec.message());
  std::sort(out.begin(), out.end(), [](const Sequence& a, const Sequence& b) { return a.name < b.name; });
  if (out.empty()) {
    throw Error("--suite " + root.string() +
                ": no sequences found (a sequence is a folder with rgb.txt, depth.txt, camera.yaml; "
                "render the room suite with scripts/room_suite.sh)");
  }
  return out;
}

// "name=--dynamic oracle --keyframe-policy adaptive" -> {name, {--dynamic, oracle, ...}}.
Variant parse_variant(const std::string& spec) {
  const auto eq = spec.find('=');
  if (eq == std::string::npos || eq == 0) {
    throw Error("--variant '" + spec + "': expected NAME=RUN ARGS (e.g. \"oracle=--dynamic oracle\")");
  }
  Variant v{spec.substr(0, eq), {}};
  if (v.name.rfind("peer:", 0) == 0) throw Error("--variant '" + spec + "': names peer:* are reserved");
  std::istringstream in(spec.substr(eq + 1));
  for (std::string a; in >> a;) v.args.push_back(a);
  return v;
}

std::vector<Variant> all_variants(const BenchArgs& args) {
  std::vector<Variant> out;
  if (args.ablation != "none" || args.variant_specs.empty()) out = variants_for(args.ablation);
  for (const auto& spec : args.variant_specs) out.push_back(parse_variant(spec));
  std::set<std::string> names;
  for (const auto& v : out) {
    if (!names.insert(v.name).second) throw Error("variant '" + v.name + "' given twice");
  }
  return out;
}

std::string dir_name_of(const std::string& variant) {
  std::string d = variant;
  for (char& c : d) {
    if (c == ':' || c == ' ' || c == '+' || c == '/' || c == '=') c = '_';
  }
  return d;
}

// ---- peers (../shared/tools/peer_<name>/run.sh): detection as run.sh does it -------------------------

std::string env_or(const char* name, const std::string& fallback) {
  const char* v = std::getenv(name);
  return v != nullptr && *v != '\0' ? std::string(v) : fallback;
}

bool nonempty_file(const std::filesystem::path& p) {
  std::error_code ec;
  return std::filesystem::is_regular_file(p, ec) && std::filesystem::file_size(p, ec) > 0;
}

struct Peer {
  std::string name;              // orbslam2 | ngdslam
  std::filesystem::path run_sh;  // ../shared/tools/peer_<name>/run.sh
  std::string missing;           // why it cannot run (empty: built)
};

Peer find_peer(const std::string& name) {
  namespace fs = std::filesystem;
  Peer p{name, fs::path(SP_SHARED_DIR) / "tools" / ("peer_" + name) / "run.sh", {}};
  if (name != "orbslam2" && name != "ngdslam")
    throw Error("--peers: unknown peer '" + name + "' (orbslam2|ngdslam)");
  if (!fs::exists(p.run_sh)) {
    p.missing = p.run_sh.string() + " not found";
    return p;
  }
  const std::string home = env_or("HOME", "/root");
  const std::string scratch =
      env_or("SCRATCH", env_or("XDG_CACHE_HOME", home + "/.cache") + "/stillpoint-peers");
  const fs::path orb_dir = env_or("ORBSLAM2_DIR", scratch + "/orbslam2");
  const fs::path dir = name == "orbslam2" ? orb_dir : fs::path(env_or("NGD_DIR", scratch + "/ngdslam"));
  const fs::path bin = dir / "Examples" / "RGB-D" / "rgbd_tum";
  std::string voc = env_or("VOC", "");
  if (voc.empty()) {
    voc = (dir / "Vocabulary" / "ORBvoc.txt").string();
    if (!nonempty_file(voc)) voc = (orb_dir / "Vocabulary" / "ORBvoc_trained_k10L5.txt").string();
  }
  const std::string setup = (p.run_sh.parent_path() / "setup.sh").string();
  if (access(bin.c_str(), X_OK) != 0) {
    p.missing = "not built (" + bin.string() + " missing; build it with " + setup + ")";
  } else if (!nonempty_file(voc)) {
    p.missing = "vocabulary " + voc + " missing (see " + p.run_sh.parent_path().string() + "/README.md)";
  } else if (name == "ngdslam") {
    const fs::path yolo = env_or("YOLO_DIR", (dir / "Thirdparty" / "YOLO").string());
    for (const auto& f : {env_or("YOLO_CFG", (yolo / "yolo-fastest-xl.cfg").string()),
                          env_or("YOLO_WEIGHTS", (yolo / "yolo-fastest-xl.weights").string()),
                          env_or("YOLO_NAMES", (yolo / "coco.names").string())}) {
      if (!nonempty_file(f)) p.missing = "detector file " + f + " missing";
    }
  }
  return p;
}

std::vector<std::string> data_lines(const std::filesystem::path& file) {
  std::vector<std::string> out;
  std::ifstream in(file);
  for (std::string line; std::getline(in, line);) {
    if (!line.empty() && line[0] != '#' && line.find_first_not_of(" \t\r") != std::string::npos)
      out.push_back(line);
  }
  return out;
}

// The first `max_frames` frames of a sequence for a peer (which has no --max-frames): a folder whose
// rgb.txt is cut, everything else linked to the original.
std::filesystem::path cut_sequence(const std::filesystem::path& seq, std::size_t max_frames,
                                   const std::filesystem::path& where) {
  namespace fs = std::filesystem;
  if (fs::exists(where)) {  // a previous bench's cut: only links and rgb.txt, nothing else is removed
    for (const auto& e : fs::directory_iterator(where)) {
      if (!e.is_symlink() && e.path().filename() != "rgb.txt")
        throw Error("refusing to reuse " + where.string() + ": it holds " + e.path().filename().string());
    }
    for (const auto& e : std::vector<fs::directory_entry>(fs::directory_iterator(where), {}))
      fs::remove(e.path());
  }
  fs::create_directories(where);
  for (const auto& e : fs::directory_iterator(seq)) {
    if (e.path().filename() == "rgb.txt") continue;
    fs::create_symlink(fs::absolute(e.path()), where / e.path().filename());
  }
  const auto rgb = data_lines(seq / "rgb.txt");
  std::ofstream out(where / "rgb.txt");
  for (std::size_t i = 0; i < rgb.size() && i < max_frames; ++i) out << rgb[i] << "\n";
  return where;
}

// Runs a peer on one sequence into `out`, evaluates its trajectory with our eval code and writes
// out/stats.json in the shape `run` writes (frames, lost_frames, fps, stages_ms.frame, eval).
// flat: the peer at nice 0 and, where its example honours NGD_NO_PACE (NGD-SLAM's, with the
// measurement edit of scripts/speed_vs_ngd.sh), without the sleep to the recorded frame times.
std::pair<int, nlohmann::json> run_peer(const Peer& peer, const std::filesystem::path& seq,
                                        const std::filesystem::path& out, bool flat) {
  const auto traj = out / "trajectory.txt";
  std::filesystem::remove(traj);
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<std::string> env{"NICE=0"};
  if (flat) env.emplace_back("NGD_NO_PACE=1");
  const int rc =
      spawn_and_wait({"/bin/bash", peer.run_sh.string(), seq.string(), traj.string()}, out / "log.txt", env);
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  nlohmann::json s = nlohmann::json::object();
  const auto frames = data_lines(seq / "rgb.txt").size();
  s["peer"] = peer.name;
  s["dataset"] = seq.string();
  s["frames"] = frames;
  std::string log;
  for (const auto& f : {out / "log.txt", std::filesystem::path(traj.string() + ".log")}) {
    std::ifstream in(f);
    log += std::string(std::istreambuf_iterator<char>(in), {}) + "\n";
  }
  const bench::PeerSpeed speed = bench::peer_speed(log, frames, wall);
  s["wall_s"] = speed.wall_s;
  s["fps"] = speed.fps;
  s["fps_source"] = speed.frame_loop ? "frame loop and shutdown" : "whole binary (start-up included)";
  // The frame-loop wall and the NGD_NO_PACE switch come from the same measurement edit, so an example
  // that prints the one honours the other.
  s["paced"] = !(flat && speed.frame_loop);
  if (speed.track_ms) s["stages_ms"]["frame"] = {{"median_ms", *speed.track_ms}};
  if (nonempty_file(traj)) {
    try {
      const auto est = io::read_tum_trajectory(traj);
      s["tracked_frames"] = est.size();
      s["lost_frames"] = frames > est.size() ? frames - est.size() : 0;
      if (std::filesystem::exists(seq / "groundtruth.txt")) {
        const auto gt = io::read_tum_trajectory(seq / "groundtruth.txt");
        s["eval"] = eval::to_json(eval::evaluate(gt, est, eval::EvalOptions{}));
        // The rule our runs' trajectory_every_frame.txt follows, for peers that leave lost frames out.
        const auto stamps = eval::read_frame_stamps(seq / "rgb.txt");
        const auto filled = eval::fill_missing_frames(stamps, est, eval::MissingFrames::Interpolate);
        const auto all = eval::evaluate(gt, filled.poses, eval::EvalOptions{});
        s["every_frame"] = eval::to_json(filled, stamps.size());
        s["every_frame"]["ate_rmse_m"] = all.ate.rmse;
        s["every_frame"]["ate_max_m"] = all.ate.max;
      }
    } catch (const std::exception& e) {
      spdlog::warn("peer {}: evaluation failed: {}", peer.name, e.what());
    }
  } else {
    s["lost_frames"] = frames;
  }
  std::ofstream(out / "stats.json") << s.dump(2) << "\n";
  return {rc == 0 && !nonempty_file(traj) ? 2 : rc, s};
}

// ---- tables over repeats and sequences --------------------------------------------------------------

std::string fmt_opt(const std::optional<double>& v, const char* f = "{:.2f}") {
  return v ? fmt::format(fmt::runtime(f), *v) : std::string("-");
}

void print_aggregate_table(const std::vector<bench::AggregateRow>& rows, int repeats) {
  std::size_t w = 28;
  for (const auto& r : rows) w = std::max(w, r.sequence.size());
  fmt::print("\nMedians over {} repeat(s) per sequence and variant\n", repeats);
  fmt::print("{:<{}} {:<24} {:>4} | {:>7} {:>15} {:>7} {:>7} | {:>6} {:>6} {:>7} {:>7} | {:>5} {:>5}\n",
             "sequence", w, "variant", "runs", "ATE", "ATE min-max", "maxErr", "ATE all", "lost", "FPS",
             "trk ms", "lock ms", "cullP", "cullR");
  fmt::print("{:<{}} {:<24} {:>4} | {:>7} {:>15} {:>7} {:>7} | {:>6} {:>6} {:>7} {:>7} | {:>5} {:>5}\n", "",
             w, "", "", "cm", "cm", "cm", "cm", "", "", "median", "median", "", "");
  for (const auto& r : rows) {
    const std::string spread =
        r.ate_min_cm ? fmt::format("{:.2f}-{:.2f}", *r.ate_min_cm, *r.ate_max_cm) : std::string("-");
    fmt::print("{:<{}} {:<24} {:>4} | {:>7} {:>15} {:>7} {:>7} | {:>6} {:>6} {:>7} {:>7} | {:>5} {:>5}{}\n",
               r.sequence, w, r.variant, r.runs, fmt_opt(r.ate_cm), spread, fmt_opt(r.max_error_cm),
               fmt_opt(r.ate_every_frame_cm), fmt_opt(r.lost_frames, "{:.0f}"), fmt_opt(r.fps, "{:.1f}"),
               fmt_opt(r.track_ms, "{:.1f}"), fmt_opt(r.lock_ms, "{:.2f}"), fmt_opt(r.cull_precision),
               fmt_opt(r.cull_recall), r.failed > 0 ? fmt::format("  ({} failed)", r.failed) : std::string());
  }
  fmt::print(
      "ATE = RMSE after SE(3) alignment; maxErr = largest per-frame translation error after the same "
      "alignment;\nATE all = ATE with a pose for every frame (lost frames interpolated across their gap, "
      "as `eval --fill-missing\ninterpolate`): like for like with peers that write a pose for each "
      "frame;\nlock ms = median per frame of the time the tracking thread held the map "
      "lock;\ncullP/cullR = culling precision/recall against the ground-truth masks (stats.json "
      "culling_score).\n");
}

void print_summary(const std::vector<bench::SummaryRow>& rows, const std::string& oracle) {
  std::size_t w = 24;
  for (const auto& r : rows) w = std::max(w, r.variant.size());
  fmt::print("\nSummary per variant over the sequences (per-sequence medians over repeats)\n");
  fmt::print("{:<12} {:<{}} {:>4} | {:>7} {:>7} {:>8} | {:>6} {:>6} | {:>7} {:>7} | {:>4}\n", "group",
             "variant", w, "seqs", "ATE med", "ATE max", "maxErr", "lost", "FPS", "/oracle", "/oracle",
             "fail");
  fmt::print("{:<12} {:<{}} {:>4} | {:>7} {:>7} {:>8} | {:>6} {:>6} | {:>7} {:>7} | {:>4}\n", "", "", w, "",
             "cm", "cm", "worst cm", "total", "median", "median", "worst", "runs");
  std::string group;
  for (const auto& r : rows) {
    if (!group.empty() && r.group != group) fmt::print("\n");
    group = r.group;
    const std::string seqs = r.with_ate == r.sequences ? fmt::format("{}", r.sequences)
                                                       : fmt::format("{}/{}", r.with_ate, r.sequences);
    fmt::print("{:<12} {:<{}} {:>4} | {:>7} {:>7} {:>8} | {:>6.0f} {:>6} | {:>7} {:>7} | {:>4}\n", r.group,
               r.variant, w, seqs, fmt_opt(r.ate_median_cm), fmt_opt(r.ate_worst_cm),
               fmt_opt(r.max_error_worst_cm), r.lost_frames_total, fmt_opt(r.fps_median, "{:.1f}"),
               fmt_opt(r.oracle_ratio_median), fmt_opt(r.oracle_ratio_worst), r.failed_runs);
  }
  fmt::print(
      "seqs = sequences with an ATE (/ run); ATE max = worst sequence; fail = runs with a non-zero exit.\n");
  if (oracle.empty()) {
    fmt::print("/oracle: no oracle variant ran (add one, e.g. --variant \"oracle=--dynamic oracle\").\n");
  } else {
    fmt::print("/oracle = ATE / ATE of '{}' on the same sequence.\n", oracle);
  }
}

void run_bench(const BenchArgs& args) {
  namespace fs = std::filesystem;
  if (args.repeats < 1) throw Error("--repeats must be at least 1");
  std::vector<Sequence> sequences;
  if (!args.suite.empty()) sequences = discover_suite(args.suite);
  const std::vector<std::string> listed =
      args.sequences.empty() && args.suite.empty() ? default_sequences() : args.sequences;
  for (const auto& s : listed) sequences.push_back({s, fs::path(s).filename().string()});
  if (sequences.empty())
    throw Error(
        "no sequences: pass --suite DIR, --sequences DIR... or render the dev set into $DYNSYNTH_DATA");
  std::set<std::string> seen;
  for (const auto& s : sequences) {
    // The name becomes a folder under --out: it must stay inside it.
    const fs::path name(s.name);
    if (s.name.empty() || name.is_absolute() ||
        std::any_of(name.begin(), name.end(), [](const fs::path& c) { return c == ".." || c == "."; }))
      throw Error("sequence " + s.dir.string() + ": cannot use '" + s.name + "' as an output folder name");
    if (!seen.insert(s.name).second)
      throw Error("two sequences named '" + s.name + "' (" + s.dir.string() + ")");
  }
  const std::vector<Variant> variants = all_variants(args);
  std::string oracle;
  for (const auto& v : variants) {
    if (oracle.empty() && bench::is_oracle_variant(v.name, v.args)) oracle = v.name;
  }
  std::vector<Peer> peers;
  nlohmann::json skipped_peers = nlohmann::json::array();
  for (const auto& name : args.peers) {
    Peer p = find_peer(name);
    if (!p.missing.empty()) {
      spdlog::warn("peer {} skipped: {}", name, p.missing);
      skipped_peers.push_back({{"peer", name}, {"reason", p.missing}});
    } else {
      peers.push_back(std::move(p));
    }
  }

  std::string model = args.detector_model;
  const auto shared_model = fs::path(SP_SHARED_DIR) / "models" / "yolox_nano.onnx";
  if (model.empty() && fs::exists(shared_model)) model = shared_model.string();
  const std::string self = fs::read_symlink("/proc/self/exe").string();
  const std::size_t total = sequences.size() * (variants.size() + peers.size()) * args.repeats;
  std::size_t done = 0;
  nlohmann::json rows = nlohmann::json::array();
  std::vector<bench::RunMetrics> metrics;
  auto rep_dir = [&](const fs::path& base, int rep) {
    return args.repeats > 1 ? base / ("rep" + std::to_string(rep)) : base;
  };
  auto record = [&](const Sequence& seq, const std::string& variant, const std::vector<std::string>& vargs,
                    int rep, int rc, const nlohmann::json& stats, const fs::path& out) {
    nlohmann::json row = summarize_row(seq.name, Variant{variant, vargs}, rc, stats);
    row["repeat"] = rep;
    row["sequence_dir"] = seq.dir.string();
    row["variant_args"] = vargs;
    row["out"] = out.string();
    if (row.contains("ate")) row["max_frame_error"] = row["ate"].value("max", 0.0);  // metres
    metrics.push_back(bench::metrics_from_row(row));
    rows.push_back(std::move(row));
    if (rc != 0) spdlog::warn("run failed (exit {}), see {}", rc, (out / "log.txt").string());
  };

  for (const auto& seq : sequences) {
    for (const auto& v : variants) {
      for (int rep = 0; rep < args.repeats; ++rep) {
        const auto out = rep_dir(fs::path(args.out) / seq.name / dir_name_of(v.name), rep);
        fs::create_directories(out);
        fs::remove(out / "stats.json");  // never read a previous bench's figures
        std::vector<std::string> argv{self,    "run",        "--dataset",    seq.dir.string(),
                                      "--out", out.string(), "--no-progress"};
        if (!model.empty()) argv.insert(argv.end(), {"--detector-model", model});
        if (!args.config.empty()) argv.insert(argv.end(), {"--config", args.config});
        if (args.deterministic) argv.emplace_back("--deterministic");
        if (args.max_frames > 0) argv.insert(argv.end(), {"--max-frames", std::to_string(args.max_frames)});
        argv.insert(argv.end(), v.args.begin(), v.args.end());
        argv.insert(argv.end(), args.extra.begin(), args.extra.end());
        spdlog::info("bench [{}/{}]: {} [{}]{}", ++done, total, seq.name, v.name,
                     args.repeats > 1 ? fmt::format(" rep {}", rep) : std::string());
        const int rc = spawn_and_wait(argv, out / "log.txt");
        nlohmann::json stats;
        if (std::ifstream in(out / "stats.json"); in) stats = nlohmann::json::parse(in, nullptr, false);
        if (stats.is_discarded() || stats.is_null()) stats = nlohmann::json::object();
        record(seq, v.name, v.args, rep, rc, stats, out);
      }
    }
    for (const auto& peer : peers) {
      const std::string name = "peer:" + peer.name;
      const auto base = fs::path(args.out) / seq.name / dir_name_of(name);
      fs::path input = seq.dir;
      if (args.max_frames > 0) input = cut_sequence(seq.dir, args.max_frames, base / "input");
      for (int rep = 0; rep < args.repeats; ++rep) {
        const auto out = rep_dir(base, rep);
        fs::create_directories(out);
        spdlog::info("bench [{}/{}]: {} [{}]{}", ++done, total, seq.name, name,
                     args.repeats > 1 ? fmt::format(" rep {}", rep) : std::string());
        const auto [rc, stats] = run_peer(peer, input, out, args.peer_pace == "flat");
        record(seq, name, {}, rep, rc, stats, out);
      }
    }
  }

  const bool suite_mode =
      !args.suite.empty() || args.repeats > 1 || !args.variant_specs.empty() || !peers.empty();
  if (args.suite.empty()) {
    print_table(rows);
    print_loop_table(rows);
  }
  const auto aggregated = bench::aggregate_repeats(metrics);
  const auto summary = bench::summarize(aggregated, oracle);
  if (suite_mode) print_aggregate_table(aggregated, args.repeats);
  print_summary(summary, oracle);
  for (const auto& s : skipped_peers) {
    fmt::print("peer {} skipped: {}\n", s["peer"].get<std::string>(), s["reason"].get<std::string>());
  }

  nlohmann::json j{{"runs", rows}, {"repeats", args.repeats}, {"oracle_variant", oracle}};
  if (!args.suite.empty()) j["suite"] = args.suite;
  j["variants"] = nlohmann::json::array();
  for (const auto& v : variants) j["variants"].push_back({{"name", v.name}, {"args", v.args}});
  for (const auto& p : peers)
    j["variants"].push_back({{"name", "peer:" + p.name}, {"run_sh", p.run_sh.string()}});
  j["peers_skipped"] = skipped_peers;
  j["aggregated"] = nlohmann::json::array();
  for (const auto& r : aggregated) j["aggregated"].push_back(bench::to_json(r));
  j["summary"] = nlohmann::json::array();
  for (const auto& r : summary) j["summary"].push_back(bench::to_json(r));
  const std::string json_file = args.json.empty() ? (fs::path(args.out) / "bench.json").string() : args.json;
  fs::create_directories(fs::absolute(json_file).parent_path());
  std::ofstream(json_file) << j.dump(2) << "\n";
  fmt::print("JSON: {}\n", json_file);
}

}  // namespace

void add_bench_command(CLI::App& app) {
  auto args = std::make_shared<BenchArgs>();
  CLI::App* cmd = app.add_subcommand(
      "bench",
      "Benchmark: sequences x variants x repeats -> tables (ATE/RPE, ms per stage, memory; medians over "
      "repeats and a per-variant summary) + JSON");
  cmd->add_option("--sequences", args->sequences,
                  "Sequence folders (default without --suite: the dev set in $DYNSYNTH_DATA + the real "
                  "kitchen); named by their folder name");
  cmd->add_option("--suite", args->suite,
                  "Run every sequence folder (one with rgb.txt) found recursively under DIR, named by its "
                  "path relative to DIR (e.g. tune/room101_walking_xyz); the summary is also grouped by the "
                  "first path component (tune / heldout)");
  cmd->add_option("--repeats", args->repeats,
                  "Runs per sequence and variant (outputs in OUT/SEQ/VARIANT/rep0, rep1, ... when > 1); the "
                  "tables report medians and the ATE spread (use 3 for threaded figures)")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  cmd->add_option("--variant,--variants", args->variant_specs,
                  "Custom variant NAME=RUN ARGS, repeatable (e.g. --variant \"oracle=--dynamic oracle\" "
                  "--variant \"adaptive=--keyframe-policy adaptive\"); run args split on spaces. Added to "
                  "--ablation's variants; without --ablation only the custom variants run ('NAME=' is the "
                  "default configuration)");
  cmd->add_option(
         "--peers", args->peers,
         "Also run peer systems, comma-separated: orbslam2,ngdslam (../shared/tools/peer_*/run.sh, "
         "evaluated with our ATE code; shown as variants peer:NAME; FPS = frames / wall time of the "
         "peer's frame loop and shutdown where its example prints it, else of its whole binary). A peer "
         "that is not built is skipped with a warning")
      ->delimiter(',')
      ->check(CLI::IsMember({"orbslam2", "ngdslam"}));
  cmd->add_option("--peer-pace", args->peer_pace,
                  "flat: peers at nice 0 and, where the example allows it (NGD-SLAM with the measurement "
                  "edit of scripts/speed_vs_ngd.sh), not paced to the recorded 30 Hz, like our runs; "
                  "recorded: as their examples were written")
      ->check(CLI::IsMember({"flat", "recorded"}))
      ->capture_default_str();
  cmd->add_option("--ablation", args->ablation, "none|dynamic (Table V)|keyframes (culling x adaptive)|loop")
      ->capture_default_str();
  cmd->add_option("--detector-model", args->detector_model,
                  "YOLO model (default: ../shared/models/yolox_nano.onnx if present)");
  cmd->add_option("--config", args->config, "System configuration YAML");
  cmd->add_option("--out", args->out, "Folder for the runs' outputs")->capture_default_str();
  cmd->add_option("--json", args->json,
                  "JSON file (default: OUT/bench.json): every run, the medians per sequence and variant "
                  "(aggregated) and the per-variant summary");
  cmd->add_flag("--deterministic", args->deterministic,
                "Run every sequence in deterministic (lock-step) mode");
  cmd->add_option("--max-frames", args->max_frames,
                  "Frames per sequence (0 = all; peers get a copy of the sequence cut to as many frames)");
  cmd->add_option("--run-args", args->extra,
                  "Extra arguments for every run (e.g. --run-args=--loop-detector --run-args=off)");
  cmd->callback([args] { run_bench(*args); });
}

}  // namespace sp::app
