#include "stillpoint/loop/bow_vector.hpp"

#include <algorithm>
#include <cmath>

#include "stillpoint/common/error.hpp"

namespace sp::loop {

BowVector BowVector::from_entries(std::vector<Entry> entries) {
  const auto by_word = [](const Entry& a, const Entry& b) { return a.first < b.first; };
  if (!std::is_sorted(entries.begin(), entries.end(), by_word))  // merged sums arrive sorted
    std::sort(entries.begin(), entries.end(), by_word);
  BowVector v;
  v.entries_.reserve(entries.size());
  for (const auto& [word, w] : entries) {
    if (!(w >= 0.0) || !std::isfinite(w))
      throw sp::Error("BowVector: weight of word " + std::to_string(word) + " is negative or not finite");
    if (!v.entries_.empty() && v.entries_.back().first == word) {
      v.entries_.back().second += w;
    } else {
      v.entries_.emplace_back(word, w);
    }
    v.l1_norm_ += w;
  }
  return v;
}

double BowVector::weight(WordId word) const {
  const auto it = std::lower_bound(entries_.begin(), entries_.end(), word,
                                   [](const Entry& e, WordId w) { return e.first < w; });
  return it != entries_.end() && it->first == word ? it->second : 0.0;
}

void BowVector::normalize_l1() {
  const double n = l1_norm_;
  if (n <= 0.0) return;
  double sum = 0.0;
  for (auto& e : entries_) sum += (e.second /= n);
  l1_norm_ = sum;
}

double l1_score(const BowVector& a, const BowVector& b) {
  const double na = a.l1_norm();
  const double nb = b.l1_norm();
  if (na <= 0.0 || nb <= 0.0) return 0.0;
  const double ia_n = 1.0 / na, ib_n = 1.0 / nb;
  double s = 0.0;
  auto ia = a.begin();
  auto ib = b.begin();
  while (ia != a.end() && ib != b.end()) {
    if (ia->first < ib->first) {
      ++ia;
    } else if (ib->first < ia->first) {
      ++ib;
    } else {
      s += std::min(ia->second * ia_n, ib->second * ib_n);
      ++ia;
      ++ib;
    }
  }
  return std::clamp(s, 0.0, 1.0);
}

std::size_t common_words(const BowVector& a, const BowVector& b) {
  std::size_t n = 0;
  auto ia = a.begin();
  auto ib = b.begin();
  while (ia != a.end() && ib != b.end()) {
    if (ia->first < ib->first) {
      ++ia;
    } else if (ib->first < ia->first) {
      ++ib;
    } else {
      ++n;
      ++ia;
      ++ib;
    }
  }
  return n;
}

namespace {

// Sum of two word-sorted entry lists (one linear merge).
std::vector<BowVector::Entry> merge_sum(const std::vector<BowVector::Entry>& a,
                                        const std::vector<BowVector::Entry>& b) {
  std::vector<BowVector::Entry> out;
  out.reserve(a.size() + b.size());
  auto ia = a.begin();
  auto ib = b.begin();
  while (ia != a.end() || ib != b.end()) {
    if (ib == b.end() || (ia != a.end() && ia->first < ib->first)) {
      out.push_back(*ia++);
    } else if (ia == a.end() || ib->first < ia->first) {
      out.push_back(*ib++);
    } else {
      out.emplace_back(ia->first, ia->second + ib->second);
      ++ia;
      ++ib;
    }
  }
  return out;
}

}  // namespace

BowVector normalized_sum(const std::vector<const BowVector*>& vectors) {
  // Each input is already sorted by word: merge them pairwise (log2 k rounds) rather than sort the
  // concatenation, which dominated closing a 15-keyframe sequence.
  std::vector<std::vector<BowVector::Entry>> parts;
  for (const BowVector* v : vectors) {
    const double n = v->l1_norm();
    if (n <= 0.0) continue;
    std::vector<BowVector::Entry> scaled(v->begin(), v->end());
    for (auto& e : scaled) e.second /= n;
    parts.push_back(std::move(scaled));
  }
  while (parts.size() > 1) {
    std::vector<std::vector<BowVector::Entry>> next;
    for (std::size_t i = 0; i + 1 < parts.size(); i += 2) next.push_back(merge_sum(parts[i], parts[i + 1]));
    if (parts.size() % 2 == 1) next.push_back(std::move(parts.back()));
    parts = std::move(next);
  }
  BowVector sum =
      BowVector::from_entries(parts.empty() ? std::vector<BowVector::Entry>{} : std::move(parts.front()));
  sum.normalize_l1();
  return sum;
}

}  // namespace sp::loop
