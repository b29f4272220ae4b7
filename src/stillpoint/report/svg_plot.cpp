#include "stillpoint/report/svg_plot.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace sp::report {

namespace {

struct Range {
  double lo = std::numeric_limits<double>::infinity();
  double hi = -std::numeric_limits<double>::infinity();
  void add(double v) {
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  [[nodiscard]] bool valid() const { return lo <= hi; }
  [[nodiscard]] double span() const { return hi - lo; }
};

std::string fmt_tick(double v) {
  if (std::abs(v) < 1e-12) return "0";
  std::string s = fmt::format("{:.6g}", v);
  return s;
}

const char* kAxisNames[3] = {"x", "y", "z"};

}  // namespace

std::vector<double> nice_ticks(double lo, double hi, int target) {
  std::vector<double> ticks;
  if (!(hi > lo) || !std::isfinite(lo) || !std::isfinite(hi)) return ticks;
  const double raw = (hi - lo) / std::max(1, target);
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  double step = mag;
  for (double m : {1.0, 2.0, 5.0, 10.0}) {
    step = m * mag;
    if (step >= raw) break;
  }
  for (double t = std::ceil(lo / step) * step; t <= hi + step * 1e-9; t += step) ticks.push_back(t);
  return ticks;
}

std::string svg_top_view(const std::vector<PathSeries>& series,
                         const std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>>& error_pairs,
                         int width, int height) {
  // Choose the plane from the spread of the first series with points.
  int a = 0, b = 2;
  for (const PathSeries& s : series) {
    if (s.positions.size() < 2) continue;
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const auto& p : s.positions) mean += p;
    mean /= static_cast<double>(s.positions.size());
    Eigen::Vector3d var = Eigen::Vector3d::Zero();
    for (const auto& p : s.positions) var += (p - mean).cwiseAbs2();
    int smallest = 0;
    var.minCoeff(&smallest);
    a = smallest == 0 ? 1 : 0;
    b = smallest == 2 ? 1 : 2;
    break;
  }
  Range X, Y;
  for (const PathSeries& s : series)
    for (const auto& p : s.positions) {
      X.add(p[a]);
      Y.add(p[b]);
    }
  const int left = 56, right = 16, top = 16, bottom = 40;
  const int pw = width - left - right, ph = height - top - bottom;
  std::string svg =
      fmt::format(R"(<svg class="chart" viewBox="0 0 {} {}" width="{}" height="{}" role="img">)", width,
                  height, width, height);
  if (!X.valid()) return svg + R"(<text x="20" y="40">no positions</text></svg>)";
  // Equal scale: the larger span decides metres per pixel, the other axis is centred.
  const double span = std::max({X.span() / pw, Y.span() / ph, 1e-6}) * 1.08;
  const double xc = (X.lo + X.hi) / 2, yc = (Y.lo + Y.hi) / 2;
  const double x0 = xc - span * pw / 2, y0 = yc - span * ph / 2;
  auto px = [&](double v) { return left + (v - x0) / span; };
  auto py = [&](double v) { return top + ph - (v - y0) / span; };
  svg += fmt::format(R"(<rect x="{}" y="{}" width="{}" height="{}" fill="#fafafa" stroke="#bbb"/>)", left,
                     top, pw, ph);
  for (double t : nice_ticks(x0, x0 + span * pw, 6))
    svg += fmt::format(
        R"(<line x1="{0:.1f}" y1="{1}" x2="{0:.1f}" y2="{2}" stroke="#e4e4e4"/><text x="{0:.1f}" y="{3}" text-anchor="middle" class="tick">{4}</text>)",
        px(t), top, top + ph, top + ph + 14, fmt_tick(t));
  for (double t : nice_ticks(y0, y0 + span * ph, 6))
    svg += fmt::format(
        R"(<line x1="{0}" y1="{1:.1f}" x2="{2}" y2="{1:.1f}" stroke="#e4e4e4"/><text x="{3}" y="{4:.1f}" text-anchor="end" class="tick">{5}</text>)",
        left, py(t), left + pw, left - 4, py(t) + 4, fmt_tick(t));
  svg += fmt::format(R"(<text x="{}" y="{}" text-anchor="middle">{} [m]</text>)", left + pw / 2, height - 6,
                     kAxisNames[a]);
  svg += fmt::format(
      R"svg(<text x="14" y="{}" text-anchor="middle" transform="rotate(-90 14 {})">{} [m]</text>)svg",
      top + ph / 2, top + ph / 2, kAxisNames[b]);
  if (!error_pairs.empty()) {
    // At most ~400 segments: enough to show where the error is, without bloating the page.
    const std::size_t every = std::max<std::size_t>(1, error_pairs.size() / 400);
    svg += R"(<g stroke="#e33" stroke-opacity="0.35" stroke-width="0.8">)";
    for (std::size_t i = 0; i < error_pairs.size(); i += every) {
      const auto& [g, e] = error_pairs[i];
      svg += fmt::format(R"(<line x1="{:.1f}" y1="{:.1f}" x2="{:.1f}" y2="{:.1f}"/>)", px(g[a]), py(g[b]),
                         px(e[a]), py(e[b]));
    }
    svg += "</g>";
  }
  int legend_y = top + 16;
  for (const PathSeries& s : series) {
    if (s.positions.empty()) continue;
    std::string points;
    points.reserve(s.positions.size() * 14);
    for (const auto& p : s.positions) points += fmt::format("{:.1f},{:.1f} ", px(p[a]), py(p[b]));
    svg += fmt::format(
        R"(<polyline fill="none" stroke="{}" stroke-width="{}" stroke-linejoin="round" points="{}"/>)",
        s.colour, s.width, points);
    svg += fmt::format(R"(<circle cx="{:.1f}" cy="{:.1f}" r="3.5" fill="{}"/>)", px(s.positions.front()[a]),
                       py(s.positions.front()[b]), s.colour);
    svg += fmt::format(
        R"(<line x1="{}" y1="{}" x2="{}" y2="{}" stroke="{}" stroke-width="3"/><text x="{}" y="{}">{}</text>)",
        left + 10, legend_y - 4, left + 32, legend_y - 4, s.colour, left + 38, legend_y, s.label);
    legend_y += 18;
  }
  return svg + "</svg>";
}

std::string svg_line_chart(const std::vector<double>& x, const std::vector<double>& y,
                           const std::string& x_label, const std::string& y_label, const std::string& colour,
                           int width, int height) {
  const int left = 56, right = 16, top = 12, bottom = 40;
  const int pw = width - left - right, ph = height - top - bottom;
  std::string svg =
      fmt::format(R"(<svg class="chart" viewBox="0 0 {} {}" width="{}" height="{}" role="img">)", width,
                  height, width, height);
  Range X, Y;
  const std::size_t n = std::min(x.size(), y.size());
  for (std::size_t i = 0; i < n; ++i) {
    X.add(x[i]);
    Y.add(y[i]);
  }
  if (n < 2 || !X.valid()) return svg + R"(<text x="20" y="40">not enough values</text></svg>)";
  Y.lo = std::min(Y.lo, 0.0);  // errors: start the axis at zero so magnitudes compare honestly
  if (Y.span() <= 0) Y.hi = Y.lo + 1;
  if (X.span() <= 0) X.hi = X.lo + 1;
  Y.hi += Y.span() * 0.05;
  auto px = [&](double v) { return left + (v - X.lo) / X.span() * pw; };
  auto py = [&](double v) { return top + ph - (v - Y.lo) / Y.span() * ph; };
  svg += fmt::format(R"(<rect x="{}" y="{}" width="{}" height="{}" fill="#fafafa" stroke="#bbb"/>)", left,
                     top, pw, ph);
  for (double t : nice_ticks(X.lo, X.hi, 8))
    svg += fmt::format(
        R"(<line x1="{0:.1f}" y1="{1}" x2="{0:.1f}" y2="{2}" stroke="#e4e4e4"/><text x="{0:.1f}" y="{3}" text-anchor="middle" class="tick">{4}</text>)",
        px(t), top, top + ph, top + ph + 14, fmt_tick(t));
  for (double t : nice_ticks(Y.lo, Y.hi, 5))
    svg += fmt::format(
        R"(<line x1="{0}" y1="{1:.1f}" x2="{2}" y2="{1:.1f}" stroke="#e4e4e4"/><text x="{3}" y="{4:.1f}" text-anchor="end" class="tick">{5}</text>)",
        left, py(t), left + pw, left - 4, py(t) + 4, fmt_tick(t));
  svg += fmt::format(R"(<text x="{}" y="{}" text-anchor="middle">{}</text>)", left + pw / 2, height - 6,
                     x_label);
  svg +=
      fmt::format(R"svg(<text x="14" y="{}" text-anchor="middle" transform="rotate(-90 14 {})">{}</text>)svg",
                  top + ph / 2, top + ph / 2, y_label);
  std::string points;
  points.reserve(n * 14);
  for (std::size_t i = 0; i < n; ++i) points += fmt::format("{:.1f},{:.1f} ", px(x[i]), py(y[i]));
  svg += fmt::format(R"(<polyline fill="none" stroke="{}" stroke-width="1.5" points="{}"/>)", colour, points);
  return svg + "</svg>";
}

}  // namespace sp::report
