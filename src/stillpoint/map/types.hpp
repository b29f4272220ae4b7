#pragma once
#include <cstdint>
#include <limits>

namespace sp::map {

// Ids, not pointers, cross thread boundaries. Id 0 means "none".
using KeyframeId = std::uint64_t;
using PointId = std::uint64_t;
inline constexpr KeyframeId kNoKeyframe = 0;
inline constexpr PointId kNoPoint = 0;

// The map (of the Atlas, docs/robustness.md "New maps and merging") a keyframe belongs to. Map 0 is
// the first; a tracker lost for long starts the next. Its own type so it is never mixed with an id.
enum class MapId : std::uint32_t {};
inline constexpr MapId kFirstMap{0};
[[nodiscard]] constexpr std::uint32_t to_int(MapId m) { return static_cast<std::uint32_t>(m); }

}  // namespace sp::map
