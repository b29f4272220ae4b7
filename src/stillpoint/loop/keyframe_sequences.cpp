#include "stillpoint/loop/keyframe_sequences.hpp"

#include <fmt/ranges.h>
#include <spdlog/spdlog.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <unordered_set>

#include "stillpoint/common/error.hpp"
#include "stillpoint/loop/loop_detector.hpp"

namespace sp::loop {

SequenceParams SequenceParams::from_yaml(const sp::ConfigReader& r) {
  SequenceParams p;
  r.read("theta_t", p.theta_t, 1e-6, M_PI);
  r.read_choice("trigger", p.trigger, {"rising-edge", "level"});
  r.read("max_length", p.max_length, 1, 1000);
  r.read("min_length", p.min_length, 1, 1000);
  r.read("angle_to_first", p.angle_to_first);
  r.read("short_sequences_grow", p.short_sequences_grow);
  r.read("min_common_ratio", p.min_common_ratio, 0.01, 1.0);
  r.read("min_consistency", p.min_consistency, 1, 20);
  r.read("exclude_recent", p.exclude_recent, 0, 100);
  if (p.min_length > p.max_length) r.fail("min_length", "must not exceed max_length");
  return p;
}

void SequenceParams::validate() const {
  if (!(theta_t > 0.0 && theta_t <= M_PI)) throw sp::Error("keyframe sequences: theta_t must be in (0, pi]");
  if (trigger != "rising-edge" && trigger != "level")
    throw sp::Error("keyframe sequences: trigger must be rising-edge or level, not '" + trigger + "'");
  if (max_length < 1 || max_length > 1000)
    throw sp::Error("keyframe sequences: max_length must be in [1, 1000]");
  if (min_length < 1 || min_length > max_length) {
    throw sp::Error("keyframe sequences: min_length must be in [1, max_length]");
  }
  if (min_consistency < 1 || min_consistency > 20)
    throw sp::Error("keyframe sequences: min_consistency in [1, 20]");
  if (!(min_common_ratio > 0.0 && min_common_ratio <= 1.0))
    throw sp::Error("keyframe sequences: min_common_ratio must be in (0, 1]");
  if (exclude_recent < 0 || exclude_recent > 100)
    throw sp::Error("keyframe sequences: exclude_recent in [0, 100]");
}

double rotation_angle(const Eigen::Matrix3d& R_cw_a, const Eigen::Matrix3d& R_cw_b) {
  const Eigen::Matrix3d R = R_cw_b * R_cw_a.transpose();
  // Clamp: rounding can push (tr - 1) / 2 just outside [-1, 1].
  return std::acos(std::clamp((R.trace() - 1.0) / 2.0, -1.0, 1.0));
}

SequenceSegmenter::SequenceSegmenter(const SequenceParams& params) : params_(params) { params_.validate(); }

KeyframeSequence SequenceSegmenter::close() {
  KeyframeSequence s;
  s.id = next_id_++;
  s.keyframes = std::move(ids_);
  std::vector<const BowVector*> ptrs;
  for (const auto& b : bows_) ptrs.push_back(b.get());
  s.bow = normalized_sum(ptrs);
  ids_.clear();
  bows_.clear();
  return s;
}

std::optional<KeyframeSequence> SequenceSegmenter::add(KeyframeId id, const Eigen::Matrix3d& R_cw,
                                                       std::shared_ptr<const BowVector> bow) {
  std::optional<KeyframeSequence> closed;
  std::optional<double> consecutive;  // the step from the previous keyframe to this one
  if (!ids_.empty()) {
    const std::size_t length = ids_.size();  // L_S before this keyframe joins
    consecutive = rotation_angle(last_R_, R_cw);
    const double theta2 = params_.angle_to_first ? rotation_angle(first_R_, R_cw) : *consecutive;
    bool close_now = false;
    if (params_.trigger == "level") {
      close_now = theta2 >= params_.theta_t;
    } else {
      // θ1, measured the same way as θ2: the step that brought the previous keyframe (whatever sequence
      // it joined), or that keyframe's angle to the sequence's first one (0 when it is the first).
      const std::optional<double> theta1 =
          params_.angle_to_first ? std::optional<double>(rotation_angle(first_R_, last_R_)) : last_step_;
      close_now = theta1.has_value() && *theta1 < params_.theta_t && theta2 > params_.theta_t;
    }
    // L_S < min_length never closes; a sequence that would exceed L_T keyframes always closes.
    if (params_.short_sequences_grow && length < static_cast<std::size_t>(params_.min_length))
      close_now = false;
    if (length >= static_cast<std::size_t>(params_.max_length)) close_now = true;
    if (close_now) closed = close();
  }
  if (ids_.empty()) first_R_ = R_cw;
  ids_.push_back(id);
  bows_.push_back(std::move(bow));
  last_R_ = R_cw;
  last_step_ = consecutive;
  return closed;
}

std::optional<KeyframeSequence> SequenceSegmenter::flush() {
  if (ids_.empty()) return std::nullopt;
  return close();
}

SequenceLoopDetector::SequenceLoopDetector(const LoopDetectorParams& params)
    : params_(params), segmenter_(params.sequence), consistency_(params.sequence.min_consistency) {
  params_.validate();
}

std::optional<KeyframeSequence> SequenceLoopDetector::record(std::optional<KeyframeSequence> closed,
                                                             bool end_of_run) {
  if (!closed) return closed;
  if (sequences_.size() != closed->id) throw sp::Error("SequenceLoopDetector: sequence ids out of order");
  sequences_.push_back(*closed);
  spdlog::debug("sequence {} closed: keyframes {}", closed->id, fmt::join(closed->keyframes, ","));
  const bool too_short = closed->keyframes.size() < static_cast<std::size_t>(params_.sequence.min_length);
  // At the end of the run no keyframe will come to lengthen the open sequence: it is queried as it is,
  // so a path that ends with a turn back onto its start still closes (office_a_loop_walking).
  if (too_short && !(end_of_run && params_.sequence.short_sequences_grow)) closed.reset();
  return closed;
}

std::optional<KeyframeSequence> SequenceLoopDetector::file_keyframe(const KeyframeInfo& kf) {
  auto bow = std::make_shared<const BowVector>(kf.bow);
  keyframe_bow_[kf.id] = bow;
  std::optional<KeyframeSequence> closed = segmenter_.add(kf.id, kf.R_cw, std::move(bow));
  sequence_of_[kf.id] = segmenter_.open_id();
  return record(std::move(closed));
}

std::vector<LoopCandidate> SequenceLoopDetector::query_and_file(const KeyframeSequence& seq,
                                                                const CovisibilityView& view) {
  std::vector<LoopCandidate> out = query_sequence(seq, view);
  seq_db_.add(seq.id, seq.bow);
  filed_.push_back(seq.id);
  stats_.candidates += out.size();
  return out;
}

std::vector<LoopCandidate> SequenceLoopDetector::finish(const CovisibilityView& view) {
  std::lock_guard lock(mutex_);
  std::optional<KeyframeSequence> closed = record(segmenter_.flush(), /*end_of_run=*/true);
  if (!closed) return {};
  return query_and_file(*closed, view);
}

void SequenceLoopDetector::add_keyframe(const KeyframeInfo& kf) {
  std::lock_guard lock(mutex_);
  if (auto closed = file_keyframe(kf)) {
    seq_db_.add(closed->id, closed->bow);
    filed_.push_back(closed->id);
  }
}

void SequenceLoopDetector::erase_keyframe(KeyframeId id) {
  // The sequence keeps its vector (it still describes the place); the keyframe just can't be a match.
  std::lock_guard lock(mutex_);
  keyframe_bow_.erase(id);
  if (const auto it = sequence_of_.find(id); it != sequence_of_.end() && it->second < sequences_.size()) {
    std::erase(sequences_[it->second].keyframes, id);
  }
}

std::size_t SequenceLoopDetector::queries() const { return seq_db_.queries(); }

DetectorStats SequenceLoopDetector::stats() const {
  std::lock_guard lock(mutex_);
  DetectorStats s = stats_;
  s.queries = seq_db_.queries();
  s.scored_pairs += seq_db_.scored_pairs();
  return s;
}

std::vector<KeyframeSequence> SequenceLoopDetector::sequences() const {
  std::lock_guard lock(mutex_);
  return sequences_;
}

std::vector<LoopCandidate> SequenceLoopDetector::detect(const KeyframeInfo& query,
                                                        const CovisibilityView& view) {
  std::lock_guard lock(mutex_);
  ++stats_.keyframes;
  std::optional<KeyframeSequence> closed = file_keyframe(query);
  if (!closed) return {};
  return query_and_file(*closed, view);
}

std::vector<LoopCandidate> SequenceLoopDetector::query_sequence(const KeyframeSequence& seq,
                                                                const CovisibilityView& view) {
  // Neighbour sequences: those holding a keyframe covisible with one of ours, and the most recent ones.
  std::unordered_set<SequenceId> neighbours;
  for (KeyframeId kf : seq.keyframes) {
    for (KeyframeId c : view.covisible(kf, 0)) {
      const auto it = sequence_of_.find(c);
      if (it != sequence_of_.end() && it->second != seq.id) neighbours.insert(it->second);
    }
  }
  const auto n_recent = std::min(filed_.size(), static_cast<std::size_t>(params_.sequence.exclude_recent));
  neighbours.insert(filed_.end() - static_cast<std::ptrdiff_t>(n_recent), filed_.end());

  // As per keyframe: a loop must score at least as high as the least similar neighbour.
  double min_score = 1.0;
  bool any = false;
  for (SequenceId n : neighbours) {
    if (const auto s = seq_db_.score(n, seq.bow)) {
      min_score = std::min(min_score, *s);
      any = true;
    }
  }
  std::vector<DatabaseHit> hits;
  if (any) {
    hits = seq_db_.query(seq.bow, params_.sequence.min_common_ratio,
                         [&](SequenceId id) { return id == seq.id || neighbours.contains(id); });
  }
  std::unordered_map<SequenceId, double> hit_score;
  for (const auto& h : hits) hit_score[h.id] = h.score;

  // Group = the sequence and its temporal neighbours (the sequence analogue of a covisibility group).
  struct GroupScore {
    SequenceId best;
    double best_score;
    double acc;
  };
  std::vector<GroupScore> groups;
  double best_acc = 0.0;
  for (const auto& h : hits) {
    if (h.score < min_score) continue;
    GroupScore g{h.id, h.score, h.score};
    for (int d : {-1, 1}) {
      if (h.id == 0 && d < 0) continue;
      const auto it = hit_score.find(h.id + static_cast<SequenceId>(d));
      if (it == hit_score.end()) continue;
      g.acc += it->second;
      if (it->second > g.best_score) {
        g.best = it->first;
        g.best_score = it->second;
      }
    }
    best_acc = std::max(best_acc, g.acc);
    groups.push_back(g);
  }
  std::vector<GroupScore> kept;
  std::unordered_set<SequenceId> seen;
  for (const auto& g : groups) {
    if (g.acc >= params_.group_score_ratio * best_acc && seen.insert(g.best).second) kept.push_back(g);
  }

  // Re-rank inside each kept sequence in two linear passes instead of scoring all L x L keyframe
  // pairs: the matched sequence's keyframe closest to the query sequence as a whole, then the query
  // keyframe closest to that one (the pair geometric verification gets).
  std::vector<std::set<KeyframeId>> candidate_groups;
  std::vector<LoopCandidate> pairs;
  const auto bow_of = [&](KeyframeId id) -> const BowVector* {
    const auto it = keyframe_bow_.find(id);
    return it == keyframe_bow_.end() ? nullptr : it->second.get();
  };
  for (const auto& g : kept) {
    LoopCandidate best{KeyframeId{}, KeyframeId{}, -1.0};
    double best_match = -1.0;
    for (KeyframeId b : sequences_[g.best].keyframes) {
      const BowVector* mb = bow_of(b);
      if (mb == nullptr) continue;
      const double s = l1_score(seq.bow, *mb);
      ++stats_.scored_pairs;
      if (s > best_match) {
        best_match = s;
        best.match = b;
      }
    }
    if (const BowVector* mb = best_match >= 0.0 ? bow_of(best.match) : nullptr) {
      for (KeyframeId a : seq.keyframes) {
        const BowVector* qa = bow_of(a);
        if (qa == nullptr) continue;
        const double s = l1_score(*qa, *mb);
        ++stats_.scored_pairs;
        if (s > best.score) {
          best.query = a;
          best.score = s;
        }
      }
    }
    if (best.score < 0.0) continue;  // every keyframe of one side was culled
    std::set<KeyframeId> members;
    for (SequenceId n = g.best == 0 ? 0 : g.best - 1; n <= g.best + 1 && n < sequences_.size(); ++n) {
      members.insert(sequences_[n].keyframes.begin(), sequences_[n].keyframes.end());
    }
    candidate_groups.push_back(std::move(members));
    pairs.push_back(best);
  }
  const std::vector<bool> accepted = consistency_.update(candidate_groups);
  spdlog::debug(
      "sequence {} ({} kf): {} neighbours, min score {:.3f}, {} hits, best {} ({:.3f}), {} groups kept",
      seq.id, seq.keyframes.size(), neighbours.size(), any ? min_score : -1.0, hits.size(),
      hits.empty() ? -1 : static_cast<long>(hits[0].id), hits.empty() ? 0.0 : hits[0].score, kept.size());
  std::vector<LoopCandidate> out;
  for (std::size_t i = 0; i < pairs.size(); ++i) {
    if (accepted[i]) out.push_back(pairs[i]);
  }
  std::sort(out.begin(), out.end(),
            [](const LoopCandidate& a, const LoopCandidate& b) { return a.score > b.score; });
  return out;
}

}  // namespace sp::loop
