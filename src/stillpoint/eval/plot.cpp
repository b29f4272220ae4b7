// Evaluation plot drawn with OpenCV: top view of both trajectories and the errors over time.
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "stillpoint/common/error.hpp"
#include "stillpoint/eval/evaluate.hpp"

namespace sp::eval {

namespace {

const cv::Scalar kWhite(255, 255, 255), kBlack(0, 0, 0), kGrid(225, 225, 225), kFrame(90, 90, 90);
const cv::Scalar kGt(40, 40, 40), kEst(200, 110, 20), kErr(80, 80, 235), kRpe(60, 150, 40);
constexpr int kFont = cv::FONT_HERSHEY_SIMPLEX;

// Linear map from data values to pixels along one axis.
struct Axis {
  double lo, hi;  // data range
  int p0, p1;     // pixels of lo and hi (p1 < p0 for a vertical axis)
  [[nodiscard]] double px(double v) const { return p0 + (v - lo) / (hi - lo) * (p1 - p0); }
};

// A 1-2-5 step giving about `target` ticks over [lo, hi].
double nice_step(double lo, double hi, int target) {
  const double raw = (hi - lo) / target;
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0, 10.0}) {
    if (m * mag >= raw) return m * mag;
  }
  return 10 * mag;
}

std::string tick_label(double v, double step) {
  const int decimals = std::clamp(static_cast<int>(-std::floor(std::log10(step) + 1e-9)), 0, 6);
  if (std::abs(v) < step * 1e-6) v = 0;  // no "-0.00"
  return fmt::format("{:.{}f}", v, decimals);
}

void text(cv::Mat& img, const std::string& s, cv::Point org, double scale = 0.45,
          const cv::Scalar& c = kBlack, int thickness = 1) {
  cv::putText(img, s, org, kFont, scale, c, thickness, cv::LINE_AA);
}

cv::Size text_size(const std::string& s, double scale = 0.45) {
  int base = 0;
  return cv::getTextSize(s, kFont, scale, 1, &base);
}

// Frame, grid and tick labels of a panel.
void draw_axes(cv::Mat& img, const Axis& x, const Axis& y, const std::string& xlabel,
               const std::string& ylabel) {
  const cv::Rect box(cv::Point(x.p0, y.p1), cv::Point(x.p1, y.p0));
  const double sx = nice_step(x.lo, x.hi, 8), sy = nice_step(y.lo, y.hi, 6);
  for (double v = std::ceil(x.lo / sx) * sx; v <= x.hi + 1e-9 * sx; v += sx) {
    const int p = static_cast<int>(std::lround(x.px(v)));
    cv::line(img, {p, box.y}, {p, box.br().y}, kGrid, 1);
    cv::line(img, {p, box.br().y}, {p, box.br().y + 5}, kFrame, 1);
    const std::string s = tick_label(v, sx);
    text(img, s, {p - text_size(s).width / 2, box.br().y + 20});
  }
  for (double v = std::ceil(y.lo / sy) * sy; v <= y.hi + 1e-9 * sy; v += sy) {
    const int p = static_cast<int>(std::lround(y.px(v)));
    cv::line(img, {box.x, p}, {box.br().x, p}, kGrid, 1);
    cv::line(img, {box.x - 5, p}, {box.x, p}, kFrame, 1);
    const std::string s = tick_label(v, sy);
    text(img, s, {box.x - 9 - text_size(s).width, p + 5});
  }
  cv::rectangle(img, box, kFrame, 1);
  text(img, xlabel, {box.x + box.width / 2 - text_size(xlabel, 0.5).width / 2, box.br().y + 42}, 0.5);
  // Vertical label: draw horizontally into a patch and rotate it.
  const cv::Size ts = text_size(ylabel, 0.5);
  cv::Mat patch(ts.height + 8, ts.width + 4, CV_8UC3, kWhite);
  text(patch, ylabel, {2, ts.height + 2}, 0.5);
  cv::rotate(patch, patch, cv::ROTATE_90_COUNTERCLOCKWISE);
  const int px = std::max(0, box.x - 70), py = std::max(0, box.y + box.height / 2 - patch.rows / 2);
  if (px + patch.cols <= img.cols && py + patch.rows <= img.rows)
    patch.copyTo(img(cv::Rect(px, py, patch.cols, patch.rows)));
}

struct LegendItem {
  std::string label;
  cv::Scalar color;
  int thickness;
};

void draw_legend(cv::Mat& img, cv::Point top_right, const std::vector<LegendItem>& items) {
  int w = 0;
  for (const auto& it : items) w = std::max(w, text_size(it.label).width);
  const int row = 22, width = w + 56, height = row * static_cast<int>(items.size()) + 10;
  const cv::Rect box(top_right.x - width, top_right.y, width, height);
  cv::rectangle(img, box, kWhite, cv::FILLED);
  cv::rectangle(img, box, kFrame, 1);
  for (std::size_t k = 0; k < items.size(); ++k) {
    const int y = box.y + 16 + row * static_cast<int>(k);
    cv::line(img, {box.x + 8, y - 4}, {box.x + 38, y - 4}, items[k].color, items[k].thickness, cv::LINE_AA);
    text(img, items[k].label, {box.x + 46, y});
  }
}

cv::Point pt(const Axis& x, const Axis& y, double u, double v) {
  return {static_cast<int>(std::lround(x.px(u))), static_cast<int>(std::lround(y.px(v)))};
}

// A polyline that breaks where the samples have a gap (more than 5 median steps).
void draw_series(cv::Mat& img, const Axis& x, const Axis& y, const std::vector<double>& t,
                 const std::vector<double>& v, const cv::Scalar& color, int thickness) {
  if (t.size() < 2) return;
  std::vector<double> dt;
  for (std::size_t k = 1; k < t.size(); ++k) dt.push_back(t[k] - t[k - 1]);
  std::nth_element(dt.begin(), dt.begin() + static_cast<std::ptrdiff_t>(dt.size() / 2), dt.end());
  const double gap = 5 * dt[dt.size() / 2];
  for (std::size_t k = 1; k < t.size(); ++k) {
    if (t[k] - t[k - 1] > gap) continue;
    cv::line(img, pt(x, y, t[k - 1], v[k - 1]), pt(x, y, t[k], v[k]), color, thickness, cv::LINE_AA);
  }
}

}  // namespace

void write_plot(const std::filesystem::path& png, const EvalResult& r) {
  if (r.gt_positions.empty()) throw Error("write_plot: nothing to plot");
  constexpr int W = 1000;
  constexpr int left = 95, right = W - 30;

  // The two axes along which the ground truth spreads most make the top view.
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : r.gt_positions) mean += p;
  mean /= static_cast<double>(r.gt_positions.size());
  Eigen::Vector3d var = Eigen::Vector3d::Zero();
  for (const auto& p : r.gt_positions) var += (p - mean).cwiseAbs2();
  std::array<int, 3> order{0, 1, 2};
  std::sort(order.begin(), order.end(), [&](int a, int b) { return var[a] > var[b]; });
  const int ax = std::min(order[0], order[1]), ay = std::max(order[0], order[1]);
  const char* names = "xyz";

  double xlo = 1e300, xhi = -1e300, ylo = 1e300, yhi = -1e300;
  for (const auto* set : {&r.gt_positions, &r.est_positions}) {
    for (const auto& p : *set) {
      xlo = std::min(xlo, p[ax]), xhi = std::max(xhi, p[ax]);
      ylo = std::min(ylo, p[ay]), yhi = std::max(yhi, p[ay]);
    }
  }
  // Equal scale on both axes, centred, with a margin; the panel's height follows the data's aspect.
  const double aspect = (yhi - ylo + 1e-9) / (xhi - xlo + 1e-9);
  const int top_h = std::clamp(static_cast<int>((right - left) * aspect), 360, 760);
  const cv::Rect top(left, 60, right - left, top_h);
  const cv::Rect bottom(left, top.br().y + 90, right - left, 230);
  cv::Mat img(bottom.br().y + 60, W, CV_8UC3, kWhite);
  const double span = std::max({(xhi - xlo) / top.width, (yhi - ylo) / top.height, 1e-6 / top.width}) * 1.08;
  const double xc = 0.5 * (xlo + xhi), yc = 0.5 * (ylo + yhi);
  const Axis X{xc - span * top.width / 2, xc + span * top.width / 2, top.x, top.br().x};
  const Axis Y{yc - span * top.height / 2, yc + span * top.height / 2, top.br().y, top.y};

  text(img, fmt::format("Top view   ATE rmse {:.4f} m over {} poses", r.ate.rmse, r.pairs), {left, 38}, 0.65,
       kBlack, 1);
  draw_axes(img, X, Y, fmt::format("{} [m]", names[ax]), fmt::format("{} [m]", names[ay]));
  // At most ~300 error segments, so long runs stay readable.
  const std::size_t every = std::max<std::size_t>(1, (r.gt_positions.size() + 299) / 300);
  for (std::size_t k = 0; k < r.gt_positions.size(); k += every) {
    cv::line(img, pt(X, Y, r.gt_positions[k][ax], r.gt_positions[k][ay]),
             pt(X, Y, r.est_positions[k][ax], r.est_positions[k][ay]), kErr, 1, cv::LINE_AA);
  }
  std::vector<double> gx, gy, ex, ey;
  for (std::size_t k = 0; k < r.gt_positions.size(); ++k) {
    gx.push_back(r.gt_positions[k][ax]), gy.push_back(r.gt_positions[k][ay]);
    ex.push_back(r.est_positions[k][ax]), ey.push_back(r.est_positions[k][ay]);
  }
  for (std::size_t k = 1; k < gx.size(); ++k) {
    cv::line(img, pt(X, Y, gx[k - 1], gy[k - 1]), pt(X, Y, gx[k], gy[k]), kGt, 2, cv::LINE_AA);
    cv::line(img, pt(X, Y, ex[k - 1], ey[k - 1]), pt(X, Y, ex[k], ey[k]), kEst, 2, cv::LINE_AA);
  }
  cv::circle(img, pt(X, Y, gx.front(), gy.front()), 6, kGt, 2, cv::LINE_AA);
  const std::string align = r.alignment.scale != 1.0 ? "estimate (Sim3-aligned)" : "estimate (aligned)";
  draw_legend(img, {top.br().x - 8, top.y + 8},
              {{"ground truth (o = start)", kGt, 2}, {align, kEst, 2}, {"ATE error", kErr, 1}});

  // Errors over time, seconds from the first associated pose.
  const double t0 = r.stamps.front();
  double t_end = r.stamps.back() - t0, e_max = r.ate.max;
  if (!r.rpe_stamps.empty()) {
    t_end = std::max(t_end, r.rpe_stamps.back() - t0);
    e_max = std::max(e_max, r.rpe_trans.max);
  }
  const Axis T{0, std::max(t_end, 1e-3), bottom.x, bottom.br().x};
  const Axis E{0, std::max(e_max * 1.1, 1e-6), bottom.br().y, bottom.y};
  text(img,
       fmt::format("Error over time   RPE trans rmse {:.4f} m, rot rmse {:.3f} deg ({} pairs)",
                   r.rpe_trans.rmse, r.rpe_rot_deg.rmse, r.rpe_pairs),
       {left, bottom.y - 16}, 0.6);
  draw_axes(img, T, E, "time [s]", "error [m]");
  std::vector<double> ts;
  for (double s : r.stamps) ts.push_back(s - t0);
  draw_series(img, T, E, ts, r.ate_errors, kErr, 2);
  std::vector<double> rt;
  for (double s : r.rpe_stamps) rt.push_back(s - t0);
  draw_series(img, T, E, rt, r.rpe_trans_errors, kRpe, 1);
  draw_legend(img, {bottom.br().x - 8, bottom.y + 8}, {{"ATE", kErr, 2}, {"RPE trans (from t)", kRpe, 1}});

  std::error_code ec;
  if (png.has_parent_path()) std::filesystem::create_directories(png.parent_path(), ec);
  bool ok = false;
  try {
    ok = cv::imwrite(png.string(), img);
  } catch (const cv::Exception&) {
    ok = false;
  }
  if (!ok) throw Error("write_plot: cannot write " + png.string());
}

}  // namespace sp::eval
