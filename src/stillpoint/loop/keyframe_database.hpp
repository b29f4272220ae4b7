#pragma once
// Inverted file over BoW vectors: word -> ids of the entries that contain it. Map-agnostic: an id is
// whatever the caller files (keyframe ids, or sequence ids for the keyframe-sequence detector).
// Thread-safe: every method takes the database's own mutex.
#include <cstdint>
#include <functional>
#include <mutex>
#include <optional>
#include <unordered_map>
#include <vector>

#include "stillpoint/loop/bow_vector.hpp"

namespace sp::loop {

// What the caller files an entry under (a keyframe id's number, a keyframe sequence's id).
using EntryId = std::uint64_t;

struct DatabaseHit {
  EntryId id = 0;
  std::uint32_t common_words = 0;
  double score = 0.0;  // L1 score against the query
};

class KeyframeDatabase {
 public:
  // Files `bow` under `id` (replacing an earlier vector of the same id). Keeps a copy of the vector.
  void add(EntryId id, const BowVector& bow);
  // Removes `id` from the inverted file; unknown ids are ignored.
  void erase(EntryId id);
  void clear();

  [[nodiscard]] bool contains(EntryId id) const;
  [[nodiscard]] std::size_t size() const;
  // L1 score of a filed vector against `bow`; nullopt for an unknown id. Counted as a scored pair.
  [[nodiscard]] std::optional<double> score(EntryId id, const BowVector& bow) const;
  [[nodiscard]] std::optional<BowVector> bow(EntryId id) const;

  // One database query: the entries sharing words with `query`, except those `exclude` rejects,
  // that share at least min_common_ratio x (the largest number of shared words), each scored.
  // Sorted by score, best first. Counts one query and one scored pair per returned hit.
  [[nodiscard]] std::vector<DatabaseHit> query(const BowVector& query, double min_common_ratio,
                                               const std::function<bool(EntryId)>& exclude = {}) const;

  [[nodiscard]] std::size_t queries() const;
  [[nodiscard]] std::size_t scored_pairs() const;

 private:
  // Entries live in dense slots so that a query counts shared words in flat arrays, not hash maps:
  // summed sequence vectors have thousands of words, each touching several inverted lists.
  using Slot = std::uint32_t;
  struct Entry {
    EntryId id = 0;
    BowVector bow;
  };
  void erase_locked(std::unordered_map<EntryId, Slot>::iterator it);

  mutable std::mutex mutex_;
  std::vector<std::vector<Slot>> inverted_;  // indexed by word
  std::vector<Entry> entries_;               // indexed by slot
  std::vector<Slot> free_slots_;
  std::unordered_map<EntryId, Slot> slot_of_;
  mutable std::size_t queries_ = 0;
  mutable std::size_t scored_ = 0;
};

}  // namespace sp::loop
