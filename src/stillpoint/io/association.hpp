#pragma once
// Timestamp association with the semantics of the TUM benchmark's associate.py.
#include <cstddef>
#include <utility>
#include <vector>

namespace sp::io {

// Pairs (i, j) with |a[i] - (b[j] + offset)| < max_difference, chosen greedily by increasing
// difference (ties by a stamp, then b stamp), each index used at most once; sorted by a index.
std::vector<std::pair<std::size_t, std::size_t>> associate(const std::vector<double>& a,
                                                           const std::vector<double>& b, double offset,
                                                           double max_difference);

}  // namespace sp::io
