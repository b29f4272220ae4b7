#include "stillpoint/report/html_report.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstring>
#include <fstream>

#include "stillpoint/common/error.hpp"
#include "stillpoint/common/timing.hpp"
#include "stillpoint/report/svg_plot.hpp"

namespace sp::report {

namespace {

constexpr const char* kEstimateColour = "#e8710a";
constexpr const char* kGroundTruthColour = "#333333";

const char* kStyle = R"(
body{font:14px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:0;color:#222;background:#fff}
header{background:#20303f;color:#fff;padding:14px 24px}header h1{margin:0;font-size:20px}
header .sub{opacity:.8;font-size:13px}main{padding:8px 24px 40px;max-width:1400px}
h2{font-size:17px;margin:28px 0 8px;border-bottom:1px solid #ddd;padding-bottom:4px}
table{border-collapse:collapse;font-variant-numeric:tabular-nums}td,th{padding:3px 10px;border-bottom:1px solid #eee;text-align:left}
th{background:#f4f6f8}td.num{text-align:right}.missing{color:#8a5a00;background:#fff7e0;padding:6px 10px;border-left:3px solid #e0a800}
.notes li{color:#8a5a00}.bar{display:inline-block;height:9px;background:#7aa6d8;vertical-align:middle}
.bar.p95{background:#c9dbef}.tick{font-size:11px;fill:#555}svg.chart{max-width:100%;height:auto;font-size:12px}
.thumbs{display:flex;flex-wrap:wrap;gap:10px}.thumbs figure{margin:0;width:320px}.thumbs img{width:320px;display:block;border:1px solid #ccc}
.thumbs figcaption{font-size:12px;color:#555}#viewer{position:relative;width:100%;height:560px;background:#11161c;border-radius:4px}
#viewer canvas{display:block;width:100%;height:100%}.viewer-msg{color:#ddd;padding:16px}
.viewer-controls{margin:6px 0;font-size:13px}.viewer-controls label{margin-right:14px}
.legend span{display:inline-block;width:18px;height:4px;margin:0 4px 2px 10px;vertical-align:middle}
)";

// Counts script errors, console.error calls, failed loads and CSP violations on <html
// data-console-errors="N">, so a reader (and the headless-browser test) can see that the page ran
// cleanly; runs first, before any other script.
const char* kErrorMonitor =
    "(function(){const r=document.documentElement;let n=0;r.dataset.consoleErrors='0';"
    "function note(m){n+=1;r.dataset.consoleErrors=String(n);"
    "if(!r.dataset.consoleErrorFirst)r.dataset.consoleErrorFirst=String(m).slice(0,300);}"
    "const e=console.error.bind(console);console.error=function(...a){note(a.join(' '));e(...a);};"
    "window.addEventListener('error',function(ev){note(ev.message||('failed to load '+"
    "(ev.target&&(ev.target.src||ev.target.href))));},true);"
    "window.addEventListener('unhandledrejection',function(ev){note('unhandled rejection: '+ev.reason);});"
    "document.addEventListener('securitypolicyviolation',function(ev){note('CSP blocked '+ev.blockedURI);});"
    "})();";

std::string number(const nlohmann::json& j, const char* key, const char* format = "{}") {
  if (!j.is_object() || !j.contains(key) || !j[key].is_number()) return "n/a";
  if (j[key].is_number_integer()) return fmt::format(fmt::runtime(format), j[key].get<long long>());
  return fmt::format(fmt::runtime(format), j[key].get<double>());
}

std::string text(const nlohmann::json& j, const char* key) {
  if (!j.is_object() || !j.contains(key)) return "n/a";
  if (j[key].is_string()) return html_escape(j[key].get<std::string>());
  if (j[key].is_boolean()) return j[key].get<bool>() ? "yes" : "no";
  return html_escape(j[key].dump());
}

std::string row(const std::string& name, const std::string& value) {
  return fmt::format("<tr><th>{}</th><td class=\"num\">{}</td></tr>\n", name, value);
}

std::string missing(const std::string& why) { return "<p class=\"missing\">" + html_escape(why) + "</p>\n"; }

std::string floats_base64(const std::vector<float>& v) {
  return base64(std::string_view(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(float)));
}

// Positions in the frame the page shows: the ground-truth frame when an alignment exists.
std::vector<Eigen::Vector3d> shown_positions(const std::vector<io::StampedPose>& poses, const RunData& run) {
  std::vector<Eigen::Vector3d> out;
  out.reserve(poses.size());
  for (const auto& p : poses) out.push_back(run.eval ? run.eval->alignment.apply(p.t) : p.t);
  return out;
}

std::vector<float> to_floats(const std::vector<Eigen::Vector3d>& positions) {
  std::vector<float> out;
  out.reserve(positions.size() * 3);
  for (const auto& p : positions)
    for (int k = 0; k < 3; ++k) out.push_back(static_cast<float>(p[k]));
  return out;
}

nlohmann::json cloud_json(const std::optional<PointCloud>& cloud, std::size_t total, const RunData& run) {
  if (!cloud || cloud->size() == 0) return nullptr;
  std::vector<float> xyz = cloud->xyz;
  if (run.eval) {
    for (std::size_t i = 0; i + 2 < xyz.size(); i += 3) {
      const Eigen::Vector3d p = run.eval->alignment.apply(Eigen::Vector3d(xyz[i], xyz[i + 1], xyz[i + 2]));
      for (int k = 0; k < 3; ++k) xyz[i + static_cast<std::size_t>(k)] = static_cast<float>(p[k]);
    }
  }
  nlohmann::json j = {{"count", cloud->size()}, {"total", total}, {"xyz", floats_base64(xyz)}};
  if (!cloud->rgb.empty())
    j["rgb"] = base64(std::string_view(reinterpret_cast<const char*>(cloud->rgb.data()), cloud->rgb.size()));
  return j;
}

// Data for the 3-D view, as JSON inside <script type="application/json">: float32 arrays travel as
// base64 (half the size of decimal text and exact).
std::string viewer_data(const RunData& run) {
  nlohmann::json j;
  j["frame"] = run.eval ? "ground truth (estimate aligned, SE(3))" : "SLAM world (first camera)";
  const auto est = shown_positions(run.trajectory, run);
  j["estimate"] = {{"count", est.size()}, {"xyz", floats_base64(to_floats(est))}};
  if (!run.keyframes.empty()) {
    const auto kf = shown_positions(run.keyframes, run);
    j["keyframes"] = {{"count", kf.size()}, {"xyz", floats_base64(to_floats(kf))}};
  }
  if (!run.groundtruth.empty() && run.eval) {
    std::vector<Eigen::Vector3d> gt;
    for (const auto& p : run.groundtruth) gt.push_back(p.t);
    j["groundtruth"] = {{"count", gt.size()}, {"xyz", floats_base64(to_floats(gt))}};
  }
  j["map"] = cloud_json(run.map_points, run.map_points_total, run);
  j["dense"] = cloud_json(run.dense_cloud, run.dense_points_total, run);
  // Initial view: gravity is roughly the mean image-down axis of a hand-held camera, and looking
  // along the mean viewing direction shows what the camera saw.
  Eigen::Vector3d down = Eigen::Vector3d::Zero(), forward = Eigen::Vector3d::Zero();
  for (const auto& p : run.trajectory) {
    Eigen::Matrix3d R = p.q.toRotationMatrix();
    if (run.eval) R = run.eval->alignment.R * R;
    down += R.col(1);
    forward += R.col(2);
  }
  if (down.norm() > 1e-9 && forward.norm() > 1e-9) {
    const Eigen::Vector3d up = -down.normalized();
    j["up"] = {up.x(), up.y(), up.z()};
    j["forward"] = {forward.normalized().x(), forward.normalized().y(), forward.normalized().z()};
  }
  j["colours"] = {{"estimate", kEstimateColour}, {"groundtruth", "#d0d0d0"}, {"keyframes", "#4aa3ff"}};
  const std::string s = j.dump();
  // "</" would end the <script> element; "<\/" is the same JSON string.
  std::string out;
  out.reserve(s.size() + 16);
  for (std::size_t k = 0; k < s.size(); ++k) {
    out += s[k];
    if (s[k] == '<' && k + 1 < s.size() && s[k + 1] == '/') out += '\\';
  }
  return out;
}

std::string summary_section(const RunData& run) {
  const nlohmann::json& s = run.stats;
  std::string h = "<h2>Summary</h2>\n<table>\n";
  h += row("Sequence", text(s, "dataset"));
  h += row("Completed", text(s, "completed"));
  h += row("Frames", number(s, "frames"));
  h += row("Tracked frames", number(s, "tracked_frames"));
  h += row("Lost frames", number(s, "lost_frames"));
  h += row("Relocalisations", number(s, "relocalizations"));
  h += row("Keyframes (live / created)", number(s, "keyframes") + " / " + number(s, "keyframes_created"));
  h += row("Map points", number(s, "map_points"));
  h += row("FPS (whole run)", number(s, "fps", "{:.1f}"));
  h += row("Wall time", number(s, "wall_s", "{:.1f}") + " s");
  h += row("Dynamic culling", text(s, "dynamic_mode") + ", " +
                                  number(s, "culled_features_per_frame", "{:.1f}") +
                                  " features culled per frame");
  h += row("Loop closures (detector)", number(s, "loops_closed") + " (" + text(s, "loop_detector") + ")");
  h += row("Peak memory", number(s, "peak_rss_mib", "{:.0f}") + " MiB");
  // Accuracy: recomputed from the files when ground truth is at hand, else what the run stored.
  nlohmann::json e = run.eval ? eval::to_json(*run.eval) : s.value("eval", nlohmann::json());
  if (e.is_object() && e.contains("ate")) {
    h += row("ATE RMSE", number(e["ate"], "rmse", "{:.4f}") + " m");
    h += row("ATE mean / median / max", number(e["ate"], "mean", "{:.4f}") + " / " +
                                            number(e["ate"], "median", "{:.4f}") + " / " +
                                            number(e["ate"], "max", "{:.4f}") + " m");
    h += row("RPE translation RMSE (1 s)", number(e["rpe_trans"], "rmse", "{:.4f}") + " m");
    h += row("RPE rotation RMSE (1 s)", number(e["rpe_rot_deg"], "rmse", "{:.3f}") + " deg");
    h += row("Pose pairs (ATE)", number(e, "pairs"));
    // Lost frames filled (trajectory_every_frame.txt): the figure to set beside a system that writes a
    // pose for every frame.
    if (s.contains("every_frame") && s["every_frame"].contains("ate_rmse_m")) {
      h += row("ATE RMSE on every frame (lost frames interpolated)",
               number(s["every_frame"], "ate_rmse_m", "{:.4f}") + " m, max " +
                   number(s["every_frame"], "ate_max_m", "{:.4f}") + " m");
    }
  } else {
    h += row("ATE / RPE", "n/a (no ground truth)");
  }
  h += "</table>\n";
  return h;
}

std::string trajectory_section(const RunData& run) {
  std::string h = "<h2>Trajectory (top view)</h2>\n";
  if (run.trajectory.empty()) return h + missing("no estimated pose in trajectory.txt");
  std::vector<PathSeries> series;
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> pairs;
  if (run.eval) {
    series.push_back({"ground truth", kGroundTruthColour, run.eval->gt_positions, 1.5});
    series.push_back({"estimate (aligned)", kEstimateColour, run.eval->est_positions, 1.5});
    for (std::size_t i = 0; i < run.eval->gt_positions.size(); ++i)
      pairs.emplace_back(run.eval->gt_positions[i], run.eval->est_positions[i]);
  } else {
    h += missing("no ground truth: the estimate alone, in the SLAM world frame");
    series.push_back({"estimate", kEstimateColour, shown_positions(run.trajectory, run), 1.5});
  }
  h += svg_top_view(series, pairs, 760, 560);
  return h + "\n";
}

std::string error_section(const RunData& run) {
  std::string h = "<h2>Absolute trajectory error over time</h2>\n";
  if (!run.eval) return h + missing("no ground truth: no error to show");
  std::vector<double> t;
  const double t0 = run.eval->stamps.empty() ? 0 : run.eval->stamps.front();
  for (double s : run.eval->stamps) t.push_back(s - t0);
  h += svg_line_chart(t, run.eval->ate_errors, "time since the first pose [s]", "ATE [m]", "#c0392b", 760,
                      240);
  if (!run.eval->rpe_stamps.empty()) {
    std::vector<double> rt;
    for (double s : run.eval->rpe_stamps) rt.push_back(s - t0);
    h += "<h3>Relative pose error (1 s), translation</h3>\n";
    h += svg_line_chart(rt, run.eval->rpe_trans_errors, "time since the first pose [s]", "RPE [m]", "#7d3c98",
                        760, 200);
  }
  return h + "\n";
}

std::string timing_section(const RunData& run) {
  std::string h = "<h2>Per-stage timing</h2>\n";
  if (!run.stats.contains("stages_ms") || run.stats["stages_ms"].empty())
    return h + missing("stats.json has no stages_ms");
  const nlohmann::json& st = run.stats["stages_ms"];
  // Pipeline order first, the rest alphabetically.
  std::vector<std::string> names;
  for (const char* n : {"load", "extract", "dynamic", "detector", "track", "frame", "local_mapping", "loop"})
    if (st.contains(n)) names.emplace_back(n);
  for (const auto& [k, v] : st.items())
    if (std::find(names.begin(), names.end(), k) == names.end()) names.push_back(k);
  double scale = 0;
  for (const auto& n : names) scale = std::max(scale, st[n].value("p95_ms", 0.0));
  h += "<table>\n<tr><th>stage</th><th>count</th><th>median ms</th><th>p95 ms</th><th>mean ms</th><th>max "
       "ms</th><th>total s</th><th></th></tr>\n";
  for (const auto& n : names) {
    const nlohmann::json& s = st[n];
    const double med = s.value("median_ms", 0.0), p95 = s.value("p95_ms", 0.0);
    const int wm = scale > 0 ? static_cast<int>(200 * med / scale) : 0;
    const int wp = scale > 0 ? static_cast<int>(200 * std::max(0.0, p95 - med) / scale) : 0;
    h += fmt::format(
        "<tr><td>{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td "
        "class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{:.2f}</td><td><span class=\"bar\" "
        "style=\"width:{}px\"></span><span class=\"bar p95\" style=\"width:{}px\"></span></td></tr>\n",
        html_escape(n), number(s, "count"), number(s, "median_ms", "{:.2f}"), number(s, "p95_ms", "{:.2f}"),
        number(s, "mean_ms", "{:.2f}"), number(s, "max_ms", "{:.2f}"), s.value("total_ms", 0.0) / 1000.0, wm,
        wp);
  }
  h += "</table>\n<p>Bars: median (dark) and p95 (light). <code>frame</code> is the whole tracking-thread "
       "time per "
       "frame; <code>detector</code> runs on its own thread.</p>\n";
  return h;
}

std::string thumbnails_section(const RunData& run) {
  std::string h = "<h2>Dynamic-feature culling</h2>\n";
  if (run.thumbnails.empty())
    return h + missing("no thumbnails (RUN_DIR/culled/ is missing: the run predates them or wrote no frame)");
  h +=
      "<p>Red: features culled as dynamic; green: features kept; red boxes: detections judged moving, amber: "
      "detections judged static.</p>\n<div class=\"thumbs\">\n";
  for (const Thumbnail& t : run.thumbnails) {
    const std::string caption = t.features > 0
                                    ? fmt::format("frame {} · t={:.3f} s · {} of {} features culled", t.index,
                                                  t.stamp, t.culled, t.features)
                                    : fmt::format("frame {}", t.index);
    h += fmt::format(
        "<figure><img alt=\"frame {}\" "
        "src=\"data:image/jpeg;base64,{}\"><figcaption>{}</figcaption></figure>\n",
        t.index, base64(t.jpeg), caption);
  }
  return h + "</div>\n";
}

std::string viewer_section(const RunData& run, const ViewerAssets& assets) {
  std::string h = "<h2>3-D view</h2>\n";
  if (!assets.available)
    return h +
           "<div id=\"viewer\" data-viewer-status=\"unavailable\"><div class=\"viewer-msg\">3-D view "
           "unavailable: "
           "built without three.js (npm was unavailable, or SP_REPORT_THREEJS=OFF, when StillPoint was "
           "built).</div></div>\n";
  std::string notes;
  if (!run.map_points) notes += missing("no map_points.ply in the run folder: trajectories only");
  if (!run.groundtruth.empty() && !run.eval)
    notes += missing("ground truth does not overlap: not shown in 3-D");
  if (run.map_points && run.map_points->size() < run.map_points_total)
    notes += fmt::format("<p>Map points: {} of {} shown (evenly subsampled).</p>\n", run.map_points->size(),
                         run.map_points_total);
  if (run.dense_cloud && run.dense_cloud->size() < run.dense_points_total)
    notes += fmt::format("<p>Dense cloud: {} of {} points shown (evenly subsampled).</p>\n",
                         run.dense_cloud->size(), run.dense_points_total);
  h += notes;
  h += "<div class=\"viewer-controls\">"
       "<label><input type=\"checkbox\" data-layer=\"map\" checked> map points</label>"
       "<label><input type=\"checkbox\" data-layer=\"dense\" checked> dense cloud</label>"
       "<label><input type=\"checkbox\" data-layer=\"estimate\" checked> estimate</label>"
       "<label><input type=\"checkbox\" data-layer=\"keyframes\" checked> keyframes</label>"
       "<label><input type=\"checkbox\" data-layer=\"groundtruth\" checked> ground truth</label>"
       "<label>point size <input type=\"range\" id=\"point-size\" min=\"1\" max=\"8\" value=\"2\"></label>"
       "<span class=\"legend\"><span style=\"background:" +
       std::string(kEstimateColour) +
       "\"></span>estimate<span style=\"background:#d0d0d0\"></span>ground truth"
       "<span style=\"background:#4aa3ff\"></span>keyframes</span></div>\n";
  h += "<div id=\"viewer\" data-viewer-status=\"pending\"><div class=\"viewer-msg\">Loading the 3-D view "
       "(needs JavaScript and WebGL)...</div></div>\n";
  h += "<p>Drag to orbit, right-drag to pan, wheel to zoom. Frame: <span id=\"viewer-frame\"></span>. "
       "three.js " +
       html_escape(assets.three_version) + " (MIT licence) is embedded in this page.</p>\n";
  h += "<script type=\"application/json\" id=\"sp-viewer-data\">" + viewer_data(run) + "</script>\n";
  h += "<script>window.SP_THREE_SRC = " + std::string(assets.three_js_string) +
       ";\nwindow.SP_ORBIT_SRC = " + std::string(assets.orbit_controls_js_string) + ";</script>\n";
  h += "<script type=\"module\">\n" + std::string(assets.viewer_js) + "\n</script>\n";
  return h;
}

}  // namespace

std::string base64(std::string_view bytes) {
  static constexpr char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  std::size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const auto n = (static_cast<std::uint32_t>(static_cast<unsigned char>(bytes[i])) << 16) |
                   (static_cast<std::uint32_t>(static_cast<unsigned char>(bytes[i + 1])) << 8) |
                   static_cast<unsigned char>(bytes[i + 2]);
    out += kAlphabet[(n >> 18) & 63];
    out += kAlphabet[(n >> 12) & 63];
    out += kAlphabet[(n >> 6) & 63];
    out += kAlphabet[n & 63];
  }
  if (i < bytes.size()) {
    std::uint32_t n = static_cast<std::uint32_t>(static_cast<unsigned char>(bytes[i])) << 16;
    if (i + 1 < bytes.size()) n |= static_cast<std::uint32_t>(static_cast<unsigned char>(bytes[i + 1])) << 8;
    out += kAlphabet[(n >> 18) & 63];
    out += kAlphabet[(n >> 12) & 63];
    out += i + 1 < bytes.size() ? kAlphabet[(n >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

std::string html_escape(std::string_view in) {
  std::string out;
  out.reserve(in.size());
  for (char c : in) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&#39;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

std::string render_report(const RunData& run, const ViewerAssets& assets) {
  std::string name = std::filesystem::absolute(run.dir).lexically_normal().parent_path().filename().string();
  if (std::filesystem::absolute(run.dir).lexically_normal().has_filename())
    name = std::filesystem::absolute(run.dir).lexically_normal().filename().string();
  if (run.stats.contains("dataset") && run.stats["dataset"].is_string())
    name =
        std::filesystem::path(run.stats["dataset"].get<std::string>()).lexically_normal().filename().string();
  const std::string title = "StillPoint run: " + html_escape(name);
  std::string h =
      "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
      "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n"
      // Nothing may load from elsewhere: images are data: URLs, scripts are inline or blob:.
      "<meta http-equiv=\"Content-Security-Policy\" content=\"default-src 'none'; img-src data:; "
      "style-src 'unsafe-inline'; script-src 'unsafe-inline' blob:\">\n<title>" +
      title + "</title>\n<style>" + kStyle + "</style>\n<script>" + kErrorMonitor +
      "</script>\n</head>\n<body>\n";
  h += "<header><h1>" + title + "</h1><div class=\"sub\">" + html_escape(run.dir.string()) +
       "</div></header>\n<main>\n";
  if (!run.notes.empty()) {
    h += "<ul class=\"notes\">\n";
    for (const auto& n : run.notes) h += "<li>" + html_escape(n) + "</li>\n";
    h += "</ul>\n";
  }
  h += summary_section(run);
  h += trajectory_section(run);
  h += error_section(run);
  h += timing_section(run);
  h += thumbnails_section(run);
  h += viewer_section(run, assets);
  h += "</main>\n</body>\n</html>\n";
  return h;
}

ReportResult write_report(const std::filesystem::path& run_dir,
                          const std::optional<std::filesystem::path>& out, const LoadOptions& options) {
  Stopwatch watch;
  const RunData run = load_run(run_dir, options);
  const std::string html = render_report(run, viewer_assets());
  ReportResult result;
  result.file = out ? *out : run_dir / "report.html";
  if (result.file.has_parent_path()) std::filesystem::create_directories(result.file.parent_path());
  const auto tmp = result.file.string() + ".tmp";
  {
    std::ofstream f(tmp, std::ios::binary);
    if (!f) throw Error("cannot write " + result.file.string());
    f << html;
    if (!f) throw Error("cannot write " + result.file.string());
  }
  std::filesystem::rename(tmp, result.file);
  result.bytes = html.size();
  result.ms = watch.elapsed_ms();
  return result;
}

}  // namespace sp::report
