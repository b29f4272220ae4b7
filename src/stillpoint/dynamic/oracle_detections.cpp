#include "stillpoint/dynamic/oracle_detections.hpp"

#include <cmath>
#include <fstream>
#include <sstream>

#include "stillpoint/common/error.hpp"

namespace sp::dyn {

OracleDetections OracleDetections::load(const std::filesystem::path& boxes_txt,
                                        const std::vector<std::string>& class_names) {
  std::ifstream in(boxes_txt);
  if (!in) throw Error(boxes_txt.string() + ": cannot open boxes file");
  OracleDetections o;
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    const auto first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    std::istringstream ss(line);
    double t = 0;
    int id = 0, moving = 0;
    std::string cls;
    float x0 = 0, y0 = 0, x1 = 0, y1 = 0;
    if (!(ss >> t >> id >> cls >> x0 >> y0 >> x1 >> y1 >> moving)) {
      throw InputError(boxes_txt.string(), line_no,
                       "expected 'timestamp id class x0 y0 x1 y1 moving', got '" + line + "'");
    }
    std::string extra;
    if (ss >> extra)
      throw InputError(boxes_txt.string(), line_no, "unexpected text '" + extra + "' after 8 fields");
    if (x1 < x0 || y1 < y0) throw InputError(boxes_txt.string(), line_no, "box has x1 < x0 or y1 < y0");
    if (moving != 0 && moving != 1)
      throw InputError(boxes_txt.string(), line_no, "moving flag must be 0 or 1");
    Box b;
    b.id = id;
    b.moving = moving == 1;
    // Bounds are inclusive pixel indices: the box covers [x0, x1 + 1).
    b.det = {cv::Rect2f(x0, y0, x1 - x0 + 1, y1 - y0 + 1), class_index(class_names, cls), 1.f};
    o.frames_[t].push_back(b);
  }
  return o;
}

Detections OracleDetections::at(double stamp, std::size_t frame_index, bool only_moving,
                                double max_dt) const {
  Detections d;
  d.frame_index = frame_index;
  d.stamp = stamp;
  if (frames_.empty()) return d;
  auto it = frames_.lower_bound(stamp);
  if (it == frames_.end() || (it != frames_.begin() && stamp - std::prev(it)->first < it->first - stamp)) {
    it = std::prev(it);
  }
  if (std::abs(it->first - stamp) > max_dt) return d;
  d.stamp = it->first;
  for (const Box& b : it->second) {
    if (!only_moving || b.moving) d.items.push_back(b.det);
  }
  return d;
}

}  // namespace sp::dyn
