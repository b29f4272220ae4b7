#include "stillpoint/loop/loop_detector.hpp"

#include <algorithm>
#include <unordered_set>

#include "stillpoint/common/error.hpp"
#include "stillpoint/loop/global_descriptor_detector.hpp"
#include "stillpoint/loop/hybrid_detector.hpp"

namespace sp::loop {

LoopDetectorParams LoopDetectorParams::from_yaml(const sp::ConfigReader& r) {
  LoopDetectorParams p;
  r.read_choice("method", p.method, {"bow-keyframe", "bow-sequence", "netvlad", "hybrid"});
  r.read("min_common_ratio", p.min_common_ratio, 0.01, 1.0);
  r.read("group_score_ratio", p.group_score_ratio, 0.01, 1.0);
  r.read("group_size", p.group_size, 1, 100);
  r.read("min_consistency", p.min_consistency, 1, 20);
  p.sequence = SequenceParams::from_yaml(r.section("sequence"));
  p.global = GlobalDescriptorParams::from_yaml(r.section("global"));
  p.hybrid = HybridParams::from_yaml(r.section("hybrid"));
  return p;
}

HybridParams HybridParams::from_yaml(const sp::ConfigReader& r) {
  HybridParams p;
  r.read_choice("bow", p.bow, {"bow-keyframe", "bow-sequence"});
  r.read("max_distance_sq", p.max_distance_sq, 1e-6, 4.0);
  return p;
}

GlobalDescriptorParams GlobalDescriptorParams::from_yaml(const sp::ConfigReader& r) {
  GlobalDescriptorParams p;
  r.read("max_distance_sq", p.max_distance_sq, 1e-6, 4.0);
  r.read("top_k", p.top_k, 1, 50);
  return p;
}

void LoopDetectorParams::validate() const {
  if (method != "bow-keyframe" && method != "bow-sequence" && method != "netvlad" && method != "hybrid") {
    throw sp::Error("loop detector: unknown method '" + method +
                    "' (bow-keyframe | bow-sequence | netvlad | hybrid)");
  }
  if (hybrid.bow != "bow-keyframe" && hybrid.bow != "bow-sequence")
    throw sp::Error("loop detector: hybrid.bow must be bow-keyframe or bow-sequence, not '" + hybrid.bow +
                    "'");
  if (!(hybrid.max_distance_sq > 0.0 && hybrid.max_distance_sq <= 4.0))
    throw sp::Error("loop detector: hybrid.max_distance_sq must be in (0, 4]");
  if (!(global.max_distance_sq > 0.0 && global.max_distance_sq <= 4.0))
    throw sp::Error("loop detector: global.max_distance_sq must be in (0, 4]");
  if (global.top_k < 1 || global.top_k > 50)
    throw sp::Error("loop detector: global.top_k must be in [1, 50]");
  if (!(min_common_ratio > 0.0 && min_common_ratio <= 1.0))
    throw sp::Error("loop detector: min_common_ratio");
  if (!(group_score_ratio > 0.0 && group_score_ratio <= 1.0))
    throw sp::Error("loop detector: group_score_ratio");
  if (group_size < 1 || group_size > 100) throw sp::Error("loop detector: group_size must be in [1, 100]");
  if (min_consistency < 1 || min_consistency > 20)
    throw sp::Error("loop detector: min_consistency in [1, 20]");
  sequence.validate();
}

bool needs_place_model(const std::string& method) { return method == "netvlad" || method == "hybrid"; }

std::unique_ptr<LoopDetector> make_loop_detector(const std::string& method,
                                                 const LoopDetectorParams& params) {
  LoopDetectorParams p = params;
  p.method = method;
  p.validate();
  if (method == "bow-sequence") return std::make_unique<SequenceLoopDetector>(p);
  if (method == "netvlad") return std::make_unique<GlobalDescriptorLoopDetector>(p);
  if (method == "hybrid") return std::make_unique<HybridLoopDetector>(p);
  return std::make_unique<KeyframeLoopDetector>(p);
}

std::unique_ptr<LoopDetector> make_loop_detector(const LoopDetectorParams& params) {
  return make_loop_detector(params.method, params);
}

std::vector<bool> GroupConsistency::update(const std::vector<std::set<KeyframeId>>& groups) {
  std::vector<bool> accepted(groups.size(), false);
  std::vector<Group> next;
  std::vector<bool> continued(groups_.size(), false);
  for (std::size_t i = 0; i < groups.size(); ++i) {
    bool consistent_with_any = false;
    for (std::size_t j = 0; j < groups_.size(); ++j) {
      const bool overlaps = std::any_of(groups[i].begin(), groups[i].end(),
                                        [&](KeyframeId id) { return groups_[j].members.contains(id); });
      if (!overlaps) continue;
      consistent_with_any = true;
      const int count = groups_[j].count + 1;
      if (!continued[j]) {  // a previous group continues into at most one new group
        next.push_back({groups[i], count});
        continued[j] = true;
      }
      if (count >= min_consistency_) accepted[i] = true;
    }
    if (!consistent_with_any) {
      next.push_back({groups[i], 1});
      if (min_consistency_ <= 1) accepted[i] = true;
    }
  }
  groups_ = std::move(next);
  return accepted;
}

KeyframeLoopDetector::KeyframeLoopDetector(const LoopDetectorParams& params)
    : params_(params), consistency_(params.min_consistency) {
  params_.validate();
}

void KeyframeLoopDetector::add_keyframe(const KeyframeInfo& kf) { db_.add(kf.id.value(), kf.bow); }

void KeyframeLoopDetector::erase_keyframe(KeyframeId id) { db_.erase(id.value()); }

std::size_t KeyframeLoopDetector::queries() const { return db_.queries(); }

DetectorStats KeyframeLoopDetector::stats() const {
  std::lock_guard lock(mutex_);
  DetectorStats s = stats_;
  s.queries = db_.queries();
  s.scored_pairs = db_.scored_pairs();
  return s;
}

std::vector<LoopCandidate> KeyframeLoopDetector::detect(const KeyframeInfo& query,
                                                        const CovisibilityView& view) {
  std::lock_guard lock(mutex_);
  ++stats_.keyframes;
  std::vector<LoopCandidate> out;
  // Lowest similarity to the keyframes already connected to the query: a loop must look at least as
  // similar as its own neighbourhood does.
  const std::vector<KeyframeId> connected = view.covisible(query.id, 0);
  double min_score = 1.0;
  bool any = false;
  for (KeyframeId c : connected) {
    if (const auto s = db_.score(c.value(), query.bow)) {
      min_score = std::min(min_score, *s);
      any = true;
    }
  }
  const std::unordered_set<KeyframeId> excluded(connected.begin(), connected.end());
  std::vector<DatabaseHit> hits;
  if (any) {
    hits = db_.query(query.bow, params_.min_common_ratio,
                     [&](EntryId id) { return id == query.id.value() || excluded.contains(KeyframeId{id}); });
  }
  std::unordered_map<KeyframeId, double> hit_score;
  for (const auto& h : hits) hit_score[KeyframeId{h.id}] = h.score;

  // Accumulate each candidate's score over its covisibility group; the group's best keyframe stands for it.
  struct GroupScore {
    KeyframeId best;
    double best_score;
    double acc;
  };
  std::vector<GroupScore> groups;
  double best_acc = 0.0;
  for (const auto& h : hits) {
    if (h.score < min_score) continue;
    GroupScore g{KeyframeId{h.id}, h.score, h.score};
    for (KeyframeId n : view.covisible(g.best, params_.group_size)) {
      const auto it = hit_score.find(n);
      if (it == hit_score.end()) continue;
      g.acc += it->second;
      if (it->second > g.best_score) {
        g.best = n;
        g.best_score = it->second;
      }
    }
    best_acc = std::max(best_acc, g.acc);
    groups.push_back(g);
  }
  std::vector<GroupScore> kept;
  std::unordered_set<KeyframeId> seen;
  for (const auto& g : groups) {
    if (g.acc >= params_.group_score_ratio * best_acc && seen.insert(g.best).second) kept.push_back(g);
  }

  std::vector<std::set<KeyframeId>> candidate_groups;
  for (const auto& g : kept) {
    const auto cov = view.covisible(g.best, 0);
    std::set<KeyframeId> members(cov.begin(), cov.end());
    members.insert(g.best);
    candidate_groups.push_back(std::move(members));
  }
  const std::vector<bool> accepted = consistency_.update(candidate_groups);
  for (std::size_t i = 0; i < kept.size(); ++i) {
    if (accepted[i]) out.push_back({query.id, kept[i].best, kept[i].best_score});
  }
  std::sort(out.begin(), out.end(),
            [](const LoopCandidate& a, const LoopCandidate& b) { return a.score > b.score; });
  stats_.candidates += out.size();
  db_.add(query.id.value(), query.bow);
  return out;
}

}  // namespace sp::loop
