#include "stillpoint/place/training_log.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "stillpoint/common/atomic_file.hpp"
#include "stillpoint/common/error.hpp"

namespace sp::place {

namespace fs = std::filesystem;

namespace {

fs::path with_suffix(const fs::path& out, const char* suffix) { return out.string() + suffix; }

// Loss-axis top: a "nice" number (1, 2 or 5 × 10^k) above the largest loss.
double nice_ceiling(double v) {
  if (!(v > 0)) return 1.0;
  const double p = std::pow(10.0, std::floor(std::log10(v)));
  for (double m : {1.0, 2.0, 5.0, 10.0})
    if (m * p >= v) return m * p;
  return 10 * p;
}

// A numeric field of a log row. nlohmann writes NaN and ±inf as null (a diverged epoch's loss), so
// null reads back as NaN rather than refusing the whole log.
double number(const nlohmann::json& row, const char* key) {
  const auto& v = row.at(key);
  return v.is_null() ? std::numeric_limits<double>::quiet_NaN() : v.get<double>();
}

}  // namespace

void write_training_log(const fs::path& out, const std::vector<EpochStats>& rows) {
  if (out.has_parent_path()) fs::create_directories(out.parent_path());
  nlohmann::json j = nlohmann::json::array();
  std::ofstream csv(with_suffix(out, ".log.csv"));
  csv << "epoch,loss,active,lr,seconds,val_r1,val_r5,val_r10\n";
  for (const auto& r : rows) {
    nlohmann::json row = {{"epoch", r.epoch},  {"loss", r.loss},       {"active", r.active},
                          {"lr", r.lr},        {"seconds", r.seconds}, {"val_r1", nullptr},
                          {"val_r5", nullptr}, {"val_r10", nullptr}};
    csv << fmt::format("{},{:.6g},{:.6g},{:.6g},{:.3f}", r.epoch, r.loss, r.active, r.lr, r.seconds);
    if (r.val) {
      row["val_r1"] = r.val->recall[0];
      row["val_r5"] = r.val->recall[1];
      row["val_r10"] = r.val->recall[2];
      csv << fmt::format(",{:.6g},{:.6g},{:.6g}\n", r.val->recall[0], r.val->recall[1], r.val->recall[2]);
    } else {
      csv << ",,,\n";
    }
    j.push_back(std::move(row));
  }
  // Atomically: a resumed run reads this one back, and a kill mid-write must not truncate it.
  write_file_atomically(with_suffix(out, ".log.json"), j.dump(2) + "\n");
  const fs::path png = with_suffix(out, ".curve.png");
  if (!cv::imwrite(png.string(), draw_training_curve(rows)))
    throw sp::Error("cannot write the training curve " + png.string());
}

std::vector<EpochStats> read_training_log(const fs::path& out) {
  const fs::path file = with_suffix(out, ".log.json");
  std::vector<EpochStats> rows;
  std::ifstream in(file);
  if (!in) return rows;
  try {
    const auto j = nlohmann::json::parse(in);
    for (const auto& r : j) {
      EpochStats s;
      s.epoch = r.at("epoch").get<int>();
      s.loss = number(r, "loss");
      s.active = number(r, "active");
      s.lr = r.contains("lr") ? number(r, "lr") : 0.0;
      s.seconds = number(r, "seconds");
      // A null val_r1 means no validation that epoch (it cannot be NaN: a recall is a ratio of counts).
      if (r.contains("val_r1") && !r["val_r1"].is_null()) {
        RecallResult v;
        v.recall[0] = number(r, "val_r1");
        v.recall[1] = number(r, "val_r5");
        v.recall[2] = number(r, "val_r10");
        s.val = v;
      }
      rows.push_back(s);
    }
  } catch (const nlohmann::json::exception& e) {
    throw sp::InputError(file.string(), 0, std::string("not a training log: ") + e.what());
  }
  return rows;
}

cv::Mat draw_training_curve(const std::vector<EpochStats>& rows, int width, int height) {
  const cv::Scalar white(255, 255, 255), black(0, 0, 0), grid(225, 225, 225);
  const cv::Scalar loss_colour(180, 90, 20), val_colour(30, 110, 230);  // BGR: blue, orange
  const int font = cv::FONT_HERSHEY_SIMPLEX;
  cv::Mat img(height, width, CV_8UC3, white);
  const int left = 70, right = 70, top = 40, bottom = 55;
  const cv::Rect plot(left, top, width - left - right, height - top - bottom);
  if (plot.width < 50 || plot.height < 50) throw sp::Error("draw_training_curve: image too small");

  int e0 = 1, e1 = 2;
  double max_loss = 0;
  if (!rows.empty()) {
    e0 = rows.front().epoch, e1 = rows.front().epoch;
    for (const auto& r : rows) {
      e0 = std::min(e0, r.epoch), e1 = std::max(e1, r.epoch);
      if (std::isfinite(r.loss)) max_loss = std::max(max_loss, r.loss);
    }
    if (e1 == e0) e1 = e0 + 1;  // one epoch: still a non-degenerate axis
  }
  const double loss_top = nice_ceiling(max_loss);
  const auto x_of = [&](int e) {
    return plot.x + static_cast<int>(std::lround(plot.width * static_cast<double>(e - e0) / (e1 - e0)));
  };
  const auto y_of = [&](double v, double top_value) {
    const double f = std::clamp(v / top_value, 0.0, 1.0);
    return plot.y + plot.height - static_cast<int>(std::lround(plot.height * f));
  };

  // Grid, ticks and tick labels: 5 divisions on both y axes, up to ~10 epochs labelled on x.
  for (int i = 0; i <= 5; ++i) {
    const int y = plot.y + plot.height - plot.height * i / 5;
    cv::line(img, {plot.x, y}, {plot.x + plot.width, y}, grid, 1);
    cv::putText(img, fmt::format("{:.3g}", loss_top * i / 5), {8, y + 4}, font, 0.4, loss_colour, 1,
                cv::LINE_AA);
    cv::putText(img, fmt::format("{:.1f}", 0.2 * i), {plot.x + plot.width + 8, y + 4}, font, 0.4, val_colour,
                1, cv::LINE_AA);
  }
  const int step = std::max(1, (e1 - e0 + 9) / 10);
  for (int e = e0; e <= e1; e += step) {
    const int x = x_of(e);
    cv::line(img, {x, plot.y + plot.height}, {x, plot.y + plot.height + 5}, black, 1);
    const std::string t = std::to_string(e);
    cv::putText(img, t, {x - 4 * static_cast<int>(t.size()), plot.y + plot.height + 20}, font, 0.4, black, 1,
                cv::LINE_AA);
  }
  cv::rectangle(img, plot, black, 1);
  cv::putText(img, "epoch", {plot.x + plot.width / 2 - 20, height - 12}, font, 0.5, black, 1, cv::LINE_AA);
  cv::putText(img, "loss", {8, top - 14}, font, 0.5, loss_colour, 1, cv::LINE_AA);
  cv::putText(img, "val R@1", {plot.x + plot.width - 10, top - 14}, font, 0.5, val_colour, 1, cv::LINE_AA);

  // The two series; validation points only where an epoch was evaluated.
  std::vector<cv::Point> loss_pts, val_pts;
  for (const auto& r : rows) {
    if (std::isfinite(r.loss)) loss_pts.emplace_back(x_of(r.epoch), y_of(r.loss, loss_top));
    if (r.val) val_pts.emplace_back(x_of(r.epoch), y_of(r.val->recall[0], 1.0));
  }
  for (const auto& [pts, colour] : {std::pair{&loss_pts, loss_colour}, std::pair{&val_pts, val_colour}}) {
    if (pts->size() > 1) cv::polylines(img, *pts, false, colour, 2, cv::LINE_AA);
    for (const auto& p : *pts) cv::circle(img, p, 3, colour, cv::FILLED, cv::LINE_AA);
  }

  // Legend, top right inside the plot.
  const cv::Point at(plot.x + plot.width - 150, plot.y + 10);
  cv::rectangle(img, cv::Rect(at.x, at.y, 140, val_pts.empty() ? 24 : 44), white, cv::FILLED);
  cv::rectangle(img, cv::Rect(at.x, at.y, 140, val_pts.empty() ? 24 : 44), black, 1);
  cv::line(img, {at.x + 8, at.y + 12}, {at.x + 32, at.y + 12}, loss_colour, 2);
  cv::putText(img, "training loss", {at.x + 40, at.y + 16}, font, 0.4, black, 1, cv::LINE_AA);
  if (!val_pts.empty()) {
    cv::line(img, {at.x + 8, at.y + 32}, {at.x + 32, at.y + 32}, val_colour, 2);
    cv::putText(img, "val Recall@1", {at.x + 40, at.y + 36}, font, 0.4, black, 1, cv::LINE_AA);
  }
  return img;
}

}  // namespace sp::place
