#pragma once
// Loop-candidate detection over BoW vectors, independent of the map. Two methods behind one interface:
//  * "bow-keyframe": ORB-SLAM's DetectLoopCandidates + group consistency, one database query per keyframe;
//  * "bow-sequence": keyframe sequences (keyframe_sequences.hpp), one query per closed sequence.
// Two more in their own headers: "netvlad" (global_descriptor_detector.hpp) and "hybrid", BoW candidates
// re-ranked by the global descriptor (hybrid_detector.hpp).
//
// Protocol (one loop-closing thread): for every new keyframe call detect(kf, view); it files the
// keyframe itself after querying. Call add_keyframe(kf) instead for keyframes on which detection
// is skipped, and erase_keyframe(id) when the map culls a keyframe. Candidates still need geometric
// verification by the caller. All methods are thread-safe (the detector's own mutex).
#include <Eigen/Core>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <unordered_map>
#include <vector>

#include "stillpoint/common/config_reader.hpp"
#include "stillpoint/loop/keyframe_database.hpp"
#include "stillpoint/loop/keyframe_sequences.hpp"

namespace sp::loop {

struct KeyframeInfo {
  KeyframeId id;
  Eigen::Matrix3d R_cw = Eigen::Matrix3d::Identity();  // world-to-camera rotation
  BowVector bow;                                       // L1-normalised
  Eigen::VectorXf global;  // learned global descriptor (netvlad detector only; empty otherwise)
};

struct LoopCandidate {
  KeyframeId query;    // a keyframe of the query (sequence mode: any keyframe of the closed sequence)
  KeyframeId match;    // the earlier keyframe it is believed to revisit
  double score = 0.0;  // L1 score between the two keyframes' vectors
};

// What the detectors need from the map; implemented by the integrator over the covisibility graph.
class CovisibilityView {
 public:
  virtual ~CovisibilityView() = default;
  // Keyframes that share map points with `id`, most shared first; n_best <= 0 means all of them
  // (ORB-SLAM's "connected keyframes"). Unknown ids give an empty list.
  [[nodiscard]] virtual std::vector<KeyframeId> covisible(KeyframeId id, int n_best) const = 0;
};

struct DetectorStats {
  std::size_t keyframes = 0;             // keyframes given to detect()
  std::size_t queries = 0;               // inverted-file queries
  std::size_t scored_pairs = 0;          // BoW vector pairs scored (queries, min scores, re-ranking)
  std::size_t candidates = 0;            // loop candidates returned
  std::size_t descriptor_pairs = 0;      // hybrid: candidates scored by global-descriptor distance
  std::size_t vetoed_by_descriptor = 0;  // hybrid: BoW candidates dropped as too far in descriptor space
  // hybrid: candidates passed on unranked (a keyframe without descriptor)
  std::size_t undescribed_candidates = 0;
};

class LoopDetector {
 public:
  virtual ~LoopDetector() = default;
  virtual void add_keyframe(const KeyframeInfo& kf) = 0;
  virtual void erase_keyframe(KeyframeId id) = 0;
  // Candidates for `query` (best first), then files `query`. Keyframes must arrive in creation order.
  virtual std::vector<LoopCandidate> detect(const KeyframeInfo& query, const CovisibilityView& view) = 0;
  // End of the run: queries what is still pending (the open keyframe sequence), so a loop closed by
  // the last keyframes is not lost. Per-keyframe detection has nothing pending.
  virtual std::vector<LoopCandidate> finish(const CovisibilityView& view) = 0;
  [[nodiscard]] virtual std::size_t queries() const = 0;
  [[nodiscard]] virtual DetectorStats stats() const = 0;
  [[nodiscard]] virtual std::string name() const = 0;
  // True when KeyframeInfo::global must be filled (a place model is needed).
  [[nodiscard]] virtual bool uses_global_descriptors() const { return false; }
};

// Learned global descriptors (method "netvlad"); descriptors are L2-normalised, so d² is in [0, 4].
struct GlobalDescriptorParams {
  double max_distance_sq = 1.2;  // candidates farther than this never count [d²], (0, 4]
  int top_k = 3;                 // nearest survivors checked per query [count], 1..50
  static GlobalDescriptorParams from_yaml(const sp::ConfigReader& r);
};

// BoW candidates re-ranked by the global descriptor (method "hybrid").
struct HybridParams {
  // The detector whose candidates are re-ranked: bow-keyframe | bow-sequence.
  std::string bow = "bow-sequence";
  double max_distance_sq = 1.2;  // candidates whose descriptors are farther apart are dropped [d²], (0, 4]
  static HybridParams from_yaml(const sp::ConfigReader& r);
};

struct LoopDetectorParams {
  std::string method = "bow-keyframe";  // bow-keyframe | bow-sequence | netvlad | hybrid
  double min_common_ratio = 0.8;        // candidates share >= ratio x the most shared words [-], (0, 1]
  double group_score_ratio = 0.75;      // group scores >= ratio x the best group score [-], (0, 1]
  int group_size = 10;                  // covisible keyframes in a candidate's score group [count], 1..100
  int min_consistency = 3;              // consecutive keyframes a candidate group must persist [count], 1..20
  SequenceParams sequence;              // bow-sequence only (YAML section "sequence")
  GlobalDescriptorParams global;        // netvlad only (YAML section "global")
  HybridParams hybrid;                  // hybrid only (YAML section "hybrid")

  static LoopDetectorParams from_yaml(const sp::ConfigReader& r);
  void validate() const;  // throws sp::Error
};

// Whether a detector method needs a place model (ParC_NetVLAD descriptors): "netvlad" and "hybrid".
// The configuration-level twin of LoopDetector::uses_global_descriptors(), for checks made before any
// detector exists (a build without libtorch refuses these methods up front).
[[nodiscard]] bool needs_place_model(const std::string& method);

// method: "bow-keyframe", "bow-sequence", "netvlad" or "hybrid" (overrides params.method); anything
// else is an sp::Error.
std::unique_ptr<LoopDetector> make_loop_detector(const std::string& method, const LoopDetectorParams& params);
std::unique_ptr<LoopDetector> make_loop_detector(const LoopDetectorParams& params);

// ORB-SLAM's temporal consistency: a candidate is accepted once its group (a set of keyframes)
// overlaps a group that was consistent in the previous query, for min_consistency consecutive queries
// (the first appearance counts 1).
class GroupConsistency {
 public:
  explicit GroupConsistency(int min_consistency) : min_consistency_(min_consistency) {}
  // One query's candidate groups; returns which are accepted. An empty list resets the history.
  std::vector<bool> update(const std::vector<std::set<KeyframeId>>& groups);

 private:
  struct Group {
    std::set<KeyframeId> members;
    int count = 0;
  };
  int min_consistency_;
  std::vector<Group> groups_;
};

// Per-keyframe detection (ORB-SLAM2 LoopClosing::DetectLoop / KeyFrameDatabase::DetectLoopCandidates).
class KeyframeLoopDetector final : public LoopDetector {
 public:
  explicit KeyframeLoopDetector(const LoopDetectorParams& params);
  void add_keyframe(const KeyframeInfo& kf) override;
  void erase_keyframe(KeyframeId id) override;
  std::vector<LoopCandidate> detect(const KeyframeInfo& query, const CovisibilityView& view) override;
  std::vector<LoopCandidate> finish(const CovisibilityView&) override { return {}; }
  [[nodiscard]] std::size_t queries() const override;
  [[nodiscard]] DetectorStats stats() const override;
  [[nodiscard]] std::string name() const override { return "bow-keyframe"; }

 private:
  LoopDetectorParams params_;
  mutable std::mutex mutex_;
  KeyframeDatabase db_;
  GroupConsistency consistency_;
  DetectorStats stats_;
};

// Keyframe-sequence detection (Algorithm 1), see keyframe_sequences.hpp and docs/loop_sequences.md.
class SequenceLoopDetector final : public LoopDetector {
 public:
  explicit SequenceLoopDetector(const LoopDetectorParams& params);
  void add_keyframe(const KeyframeInfo& kf) override;
  void erase_keyframe(KeyframeId id) override;
  std::vector<LoopCandidate> detect(const KeyframeInfo& query, const CovisibilityView& view) override;
  std::vector<LoopCandidate> finish(const CovisibilityView& view) override;
  [[nodiscard]] std::size_t queries() const override;
  [[nodiscard]] DetectorStats stats() const override;
  [[nodiscard]] std::string name() const override { return "bow-sequence"; }
  // Closed sequences so far (for diagnostics and tests).
  [[nodiscard]] std::vector<KeyframeSequence> sequences() const;

 private:
  // Files the keyframe; returns the sequence it closed, if any (mutex held).
  std::optional<KeyframeSequence> file_keyframe(const KeyframeInfo& kf);
  // Records a closed sequence; returns it when it is long enough to be queried and filed.
  // (At the end of the run a short open sequence is still returned, see finish()).
  std::optional<KeyframeSequence> record(std::optional<KeyframeSequence> closed, bool end_of_run = false);
  // Queries a closed sequence, then files it (mutex held).
  std::vector<LoopCandidate> query_and_file(const KeyframeSequence& seq, const CovisibilityView& view);
  std::vector<LoopCandidate> query_sequence(const KeyframeSequence& seq, const CovisibilityView& view);

  LoopDetectorParams params_;
  mutable std::mutex mutex_;
  SequenceSegmenter segmenter_;
  KeyframeDatabase seq_db_;                                 // sequence id -> sequence vector
  std::vector<KeyframeSequence> sequences_;                 // closed sequences, index = id
  std::unordered_map<KeyframeId, SequenceId> sequence_of_;  // keyframe -> its sequence (open or closed)
  // For re-ranking inside a matched sequence; shared with the segmenter's open sequence.
  std::unordered_map<KeyframeId, std::shared_ptr<const BowVector>> keyframe_bow_;
  std::vector<SequenceId> filed_;  // sequences in seq_db_, in filing order
  GroupConsistency consistency_;
  DetectorStats stats_;
};

}  // namespace sp::loop
