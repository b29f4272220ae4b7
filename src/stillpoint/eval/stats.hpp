#pragma once
// Summary statistics of error samples, with numpy's definitions (median of an even count is the mean of
// the two middle values; std is the population standard deviation).
#include <cstddef>
#include <vector>

namespace sp::eval {

struct ErrorStats {
  std::size_t count = 0;
  double rmse = 0, mean = 0, median = 0, std = 0, min = 0, max = 0;
};

// All zero for an empty input.
ErrorStats compute_stats(std::vector<double> values);

}  // namespace sp::eval
