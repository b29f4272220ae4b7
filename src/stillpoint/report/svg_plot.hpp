#pragma once
// Small inline SVG charts for the report (no JavaScript needed to see them).
#include <Eigen/Core>
#include <string>
#include <vector>

namespace sp::report {

struct PathSeries {
  std::string label;
  std::string colour;  // CSS colour
  std::vector<Eigen::Vector3d> positions;
  double width = 1.5;  // px
};

// Top view of trajectories with equal scale on both axes. The plane is the two world axes along
// which the first non-empty series spreads most (the floor plane for a hand-held camera). Thin red
// segments join `error_pairs` (gt, estimate) when given.
std::string svg_top_view(const std::vector<PathSeries>& series,
                         const std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>>& error_pairs,
                         int width, int height);

// y over x as a line with axes and ticks.
std::string svg_line_chart(const std::vector<double>& x, const std::vector<double>& y,
                           const std::string& x_label, const std::string& y_label, const std::string& colour,
                           int width, int height);

// Ticks at 1, 2 or 5 times a power of ten covering [lo, hi] (about `target` of them).
std::vector<double> nice_ticks(double lo, double hi, int target = 5);

}  // namespace sp::report
