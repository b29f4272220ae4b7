#pragma once
// A synthetic keyframe stream for the detectors: "places" along a path, each keyframe seeing 60 of its
// place's 200 words (neighbouring places share half of their words, as a continuous path does) plus 30
// words from a pool common to all places. The camera turns 0.03 rad per keyframe inside a place and
// 0.4 rad between places; covisibility links keyframes at most 4 apart in time.
#include <Eigen/Geometry>
#include <algorithm>
#include <cstdlib>
#include <random>
#include <vector>

#include "stillpoint/loop/loop_detector.hpp"

namespace sp::loop::testing {

struct Stream {
  std::vector<KeyframeInfo> keyframes;
  std::vector<int> place;  // per keyframe
  std::vector<int> visit;  // per keyframe: index of the place visit (a revisit is a new visit)
};

inline Stream make_stream(const std::vector<int>& places, int per_place, std::uint32_t seed) {
  std::mt19937 rng(seed);
  Stream s;
  double yaw = 0.0;
  std::uint64_t id = 0;  // keyframe i has id i: ids index the per-keyframe vectors
  for (std::size_t p = 0; p < places.size(); ++p) {
    yaw += 0.4;
    for (int j = 0; j < per_place; ++j) {
      if (j > 0) yaw += 0.03;
      std::vector<WordId> pool(200);
      for (int w = 0; w < 200; ++w) pool[w] = static_cast<WordId>(places[p] * 100 + w);
      std::shuffle(pool.begin(), pool.end(), rng);
      std::vector<BowVector::Entry> e;
      std::uniform_real_distribution<double> weight(0.5, 1.5);
      for (int w = 0; w < 60; ++w) e.emplace_back(pool[w], weight(rng));
      std::uniform_int_distribution<WordId> noise(100000, 100999);
      for (int w = 0; w < 30; ++w) {
        // Draws in named steps, last argument first: argument evaluation order is unspecified (GCC goes
        // right to left, clang left to right), so a clang build generated other data and failed.
        const double wt = weight(rng);
        e.emplace_back(noise(rng), wt);
      }
      KeyframeInfo kf;
      kf.id = KeyframeId{id++};
      kf.R_cw = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY()).toRotationMatrix();
      kf.bow = BowVector::from_entries(std::move(e));
      kf.bow.normalize_l1();
      s.keyframes.push_back(std::move(kf));
      s.place.push_back(places[p]);
      s.visit.push_back(static_cast<int>(p));
    }
  }
  return s;
}

// Places 0-9, then back over 2-5 (a revisit after the path has moved on), then 6.
inline std::vector<int> revisit_path() {
  std::vector<int> places;
  for (int p = 0; p < 10; ++p) places.push_back(p);
  for (int p : {2, 3, 4, 5}) places.push_back(p);
  places.push_back(6);
  return places;
}

// Covisibility of a growing map before any loop is closed: existing keyframes of the same or an
// adjacent visit (adjacent places share half their words, so their keyframes share map points) and
// those at most `radius` apart in time (nearest first).
class TemporalView final : public CovisibilityView {
 public:
  TemporalView(const Stream& s, int radius) : stream_(s), radius_(radius) {}
  void set_newest(KeyframeId id) { newest_ = id; }
  [[nodiscard]] std::vector<KeyframeId> covisible(KeyframeId id, int n_best) const override {
    std::vector<KeyframeId> out;
    const std::uint64_t n = id.value(), newest = newest_.value();
    for (std::uint64_t d = 1; d <= newest + 1; ++d) {
      for (const std::uint64_t o : {n - d, n + d}) {
        if (o > newest) continue;  // also catches n - d wrapping below 0
        const bool near = d <= static_cast<std::uint64_t>(radius_);
        if (near || std::abs(stream_.visit[o] - stream_.visit[n]) <= 1) out.emplace_back(o);
      }
    }
    if (n_best > 0 && out.size() > static_cast<std::size_t>(n_best))
      out.resize(static_cast<std::size_t>(n_best));
    return out;
  }

 private:
  const Stream& stream_;
  int radius_;
  KeyframeId newest_;
};

struct RunResult {
  std::vector<LoopCandidate> candidates;
  DetectorStats stats;
};

inline RunResult run(LoopDetector& det, const Stream& s) {
  TemporalView view(s, 4);
  RunResult r;
  for (const auto& kf : s.keyframes) {
    view.set_newest(kf.id);
    const auto c = det.detect(kf, view);
    r.candidates.insert(r.candidates.end(), c.begin(), c.end());
  }
  const auto c = det.finish(view);
  r.candidates.insert(r.candidates.end(), c.begin(), c.end());
  r.stats = det.stats();
  return r;
}

}  // namespace sp::loop::testing
