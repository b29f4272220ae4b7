#pragma once
#include <fmt/format.h>

#include <compare>
#include <cstdint>
#include <functional>
#include <limits>
#include <ostream>

namespace sp::map {

// An id of one kind of map record. Ids, not pointers, cross thread boundaries; keyframe and point ids
// are distinct types so one is never passed where the other is meant (both count up from 1 and would
// otherwise mix silently). Id 0 means "none". Built only explicitly from a number: map files and
// tests do that, the map hands out the rest.
template <class Tag>
class Id {
 public:
  using Rep = std::uint64_t;
  constexpr Id() = default;
  constexpr explicit Id(Rep value) : value_(value) {}
  [[nodiscard]] constexpr Rep value() const { return value_; }
  // The id the map hands out after this one (ids count up by one).
  [[nodiscard]] constexpr Id next() const { return Id{value_ + 1}; }
  friend constexpr auto operator<=>(Id, Id) = default;
  friend std::ostream& operator<<(std::ostream& os, Id id) { return os << id.value(); }  // test messages

 private:
  Rep value_ = 0;
};

struct KeyframeTag {};
struct PointTag {};
using KeyframeId = Id<KeyframeTag>;
using PointId = Id<PointTag>;
inline constexpr KeyframeId kNoKeyframe{};
inline constexpr PointId kNoPoint{};

// Ids written as numbers, for tests and tools that make records by hand: 3_kf, 12_pt.
namespace literals {
constexpr KeyframeId operator""_kf(unsigned long long value) { return KeyframeId{value}; }
constexpr PointId operator""_pt(unsigned long long value) { return PointId{value}; }
}  // namespace literals

// The map (of the Atlas, docs/robustness.md "New maps and merging") a keyframe belongs to. Map 0 is
// the first; a tracker lost for long starts the next. Its own type so it is never mixed with an id.
enum class MapId : std::uint32_t {};
inline constexpr MapId kFirstMap{0};
[[nodiscard]] constexpr std::uint32_t to_int(MapId m) { return static_cast<std::uint32_t>(m); }

}  // namespace sp::map

// Hashed as the number is (the identity in libstdc++), so hash containers keep the order they had
// when ids were plain integers.
template <class Tag>
struct std::hash<sp::map::Id<Tag>> {
  std::size_t operator()(sp::map::Id<Tag> id) const noexcept {
    return std::hash<std::uint64_t>{}(id.value());
  }
};

// Logged as the number.
template <class Tag>
struct fmt::formatter<sp::map::Id<Tag>> : fmt::formatter<std::uint64_t> {
  auto format(sp::map::Id<Tag> id, format_context& ctx) const {
    return fmt::formatter<std::uint64_t>::format(id.value(), ctx);
  }
};
