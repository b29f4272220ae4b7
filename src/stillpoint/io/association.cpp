#include "stillpoint/io/association.hpp"

#include <algorithm>
#include <cmath>
#include <tuple>

namespace sp::io {

std::vector<std::pair<std::size_t, std::size_t>> associate(const std::vector<double>& a,
                                                           const std::vector<double>& b, double offset,
                                                           double max_difference) {
  struct Candidate {
    double diff;
    std::size_t i, j;
  };
  // Sort b once so each a only looks at the window of b stamps that can match (associate.py tries all
  // pairs; the window is slightly wider and the exact test below decides, so the result is the same).
  std::vector<std::size_t> b_order(b.size());
  for (std::size_t j = 0; j < b.size(); ++j) b_order[j] = j;
  std::sort(b_order.begin(), b_order.end(), [&](std::size_t x, std::size_t y) { return b[x] < b[y]; });
  std::vector<double> b_sorted(b.size());
  for (std::size_t k = 0; k < b.size(); ++k) b_sorted[k] = b[b_order[k]] + offset;

  std::vector<Candidate> candidates;
  for (std::size_t i = 0; i < a.size(); ++i) {
    auto it = std::lower_bound(b_sorted.begin(), b_sorted.end(), a[i] - max_difference - 1e-6);
    for (; it != b_sorted.end() && *it <= a[i] + max_difference + 1e-6; ++it) {
      const std::size_t j = b_order[static_cast<std::size_t>(it - b_sorted.begin())];
      const double diff = std::abs(a[i] - (b[j] + offset));
      if (diff < max_difference) candidates.push_back({diff, i, j});
    }
  }
  // Python sorts (diff, a, b) tuples: ties go to the smaller a stamp, then the smaller b stamp.
  std::sort(candidates.begin(), candidates.end(), [&](const Candidate& x, const Candidate& y) {
    return std::tie(x.diff, a[x.i], b[x.j], x.i, x.j) < std::tie(y.diff, a[y.i], b[y.j], y.i, y.j);
  });
  std::vector<char> used_a(a.size(), 0), used_b(b.size(), 0);
  std::vector<std::pair<std::size_t, std::size_t>> matches;
  for (const auto& c : candidates) {
    if (used_a[c.i] || used_b[c.j]) continue;
    used_a[c.i] = used_b[c.j] = 1;
    matches.emplace_back(c.i, c.j);
  }
  std::sort(matches.begin(), matches.end());
  return matches;
}

}  // namespace sp::io
