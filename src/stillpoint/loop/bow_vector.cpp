#include "stillpoint/loop/bow_vector.hpp"

#include <algorithm>
#include <cmath>

#include "stillpoint/common/error.hpp"

namespace sp::loop {

BowVector BowVector::from_entries(std::vector<Entry> entries) {
  std::sort(entries.begin(), entries.end(), [](const Entry& a, const Entry& b) { return a.first < b.first; });
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
  }
  return v;
}

double BowVector::weight(WordId word) const {
  const auto it = std::lower_bound(entries_.begin(), entries_.end(), word,
                                   [](const Entry& e, WordId w) { return e.first < w; });
  return it != entries_.end() && it->first == word ? it->second : 0.0;
}

double BowVector::l1_norm() const {
  double s = 0.0;
  for (const auto& e : entries_) s += e.second;
  return s;
}

void BowVector::normalize_l1() {
  const double n = l1_norm();
  if (n <= 0.0) return;
  for (auto& e : entries_) e.second /= n;
}

double l1_score(const BowVector& a, const BowVector& b) {
  const double na = a.l1_norm();
  const double nb = b.l1_norm();
  if (na <= 0.0 || nb <= 0.0) return 0.0;
  double s = 0.0;
  auto ia = a.begin();
  auto ib = b.begin();
  while (ia != a.end() && ib != b.end()) {
    if (ia->first < ib->first) {
      ++ia;
    } else if (ib->first < ia->first) {
      ++ib;
    } else {
      s += std::min(ia->second / na, ib->second / nb);
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

BowVector normalized_sum(const std::vector<const BowVector*>& vectors) {
  std::vector<BowVector::Entry> all;
  for (const BowVector* v : vectors) {
    const double n = v->l1_norm();
    if (n <= 0.0) continue;
    for (const auto& [word, w] : *v) all.emplace_back(word, w / n);
  }
  BowVector sum = BowVector::from_entries(std::move(all));
  sum.normalize_l1();
  return sum;
}

}  // namespace sp::loop
