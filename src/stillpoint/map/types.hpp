#pragma once
#include <cstdint>
#include <limits>

namespace sp::map {

// Ids, not pointers, cross thread boundaries. Id 0 means "none".
using KeyframeId = std::uint64_t;
using PointId = std::uint64_t;
inline constexpr KeyframeId kNoKeyframe = 0;
inline constexpr PointId kNoPoint = 0;

}  // namespace sp::map
