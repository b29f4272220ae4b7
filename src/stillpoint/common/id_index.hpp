#pragma once
// A hash index from non-zero 64-bit ids (map point / keyframe ids; 0 is "none" there) to a slot number,
// keyed by a plain number or by an id type with value() (map::PointId),
// for tables rebuilt every frame: open addressing with linear probing in one flat array, so inserting
// allocates nothing once the capacity is reached and clear() keeps the memory. Erase shifts the
// following entries back (no tombstones), so lookups stay short after many erases.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <type_traits>
#include <utility>
#include <vector>

namespace sp {

template <class Id>
class BasicIdIndex {
 public:
  using Key = std::uint64_t;
  using Value = std::size_t;

  [[nodiscard]] const Value* find(Id id) const { return find_key(key_of(id)); }
  std::pair<Value, bool> try_emplace(Id id, Value value) { return try_emplace_key(key_of(id), value); }
  void insert_or_assign(Id id, Value value) { insert_or_assign_key(key_of(id), value); }
  bool erase(Id id) { return erase_key(key_of(id)); }

  void clear() {
    if (size_ == 0) return;
    std::fill(slots_.begin(), slots_.end(), Slot{});
    size_ = 0;
  }

  [[nodiscard]] std::size_t size() const { return size_; }
  [[nodiscard]] bool empty() const { return size_ == 0; }

 private:
  static Key key_of(Id id) {
    if constexpr (std::is_integral_v<Id>) {
      return static_cast<Key>(id);
    } else {
      return id.value();
    }
  }

  // The value stored for `key`, nullptr when none.
  [[nodiscard]] const Value* find_key(Key key) const {
    if (size_ == 0 || key == kEmpty) return nullptr;
    for (std::size_t i = home(key);; i = next(i)) {
      const Slot& s = slots_[i];
      if (s.key == key) return &s.value;
      if (s.key == kEmpty) return nullptr;
    }
  }

  // Inserts (key, value) unless the key is there; returns its stored value and whether it was inserted.
  std::pair<Value, bool> try_emplace_key(Key key, Value value) {
    Slot& s = locate(key);
    if (s.key == key) return {s.value, false};
    s = Slot{key, value};
    ++size_;
    return {value, true};
  }

  void insert_or_assign_key(Key key, Value value) {
    Slot& s = locate(key);
    if (s.key != key) ++size_;
    s = Slot{key, value};
  }

  // Removes the key if present; returns whether it was.
  bool erase_key(Key key) {
    if (size_ == 0 || key == kEmpty) return false;
    std::size_t i = home(key);
    while (slots_[i].key != key) {
      if (slots_[i].key == kEmpty) return false;
      i = next(i);
    }
    // Backward-shift: move later entries of the probe run into the hole when their home allows it.
    std::size_t hole = i;
    for (std::size_t j = next(i); slots_[j].key != kEmpty; j = next(j)) {
      const std::size_t h = home(slots_[j].key);
      // j's entry may move to the hole when its home is not cyclically inside (hole, j].
      const bool home_in_run = hole <= j ? (hole < h && h <= j) : (hole < h || h <= j);
      if (!home_in_run) {
        slots_[hole] = slots_[j];
        hole = j;
      }
    }
    slots_[hole] = Slot{};
    --size_;
    return true;
  }

  static constexpr Key kEmpty = 0;
  struct Slot {
    Key key = kEmpty;
    Value value = 0;
  };

  [[nodiscard]] std::size_t home(Key key) const {
    // Fibonacci hashing: sequential ids spread over the table.
    return static_cast<std::size_t>((key * 0x9E3779B97F4A7C15ULL) >> shift_);
  }
  [[nodiscard]] std::size_t next(std::size_t i) const { return (i + 1) & (slots_.size() - 1); }

  // The slot holding `key`, else the empty slot where it would go (growing first when needed).
  Slot& locate(Key key) {
    if (key == kEmpty) throw std::invalid_argument("IdIndex: key 0 is reserved for empty slots");
    if (2 * (size_ + 1) > slots_.size()) grow();
    std::size_t i = home(key);
    while (slots_[i].key != key && slots_[i].key != kEmpty) i = next(i);
    return slots_[i];
  }

  void grow() {
    std::vector<Slot> old = std::move(slots_);
    const std::size_t capacity = old.empty() ? 64 : 2 * old.size();
    slots_.assign(capacity, Slot{});
    shift_ = 64;
    for (std::size_t c = capacity; c > 1; c >>= 1) --shift_;
    size_ = 0;
    for (const Slot& s : old)
      if (s.key != kEmpty) {
        std::size_t i = home(s.key);
        while (slots_[i].key != kEmpty) i = next(i);
        slots_[i] = s;
        ++size_;
      }
  }

  std::vector<Slot> slots_;
  std::size_t size_ = 0;
  int shift_ = 64;
};

using IdIndex = BasicIdIndex<std::uint64_t>;

}  // namespace sp
