#pragma once
// Keyframe sequences (paper §III-B, Algorithm 1): consecutive keyframes whose viewing direction barely
// changes are grouped into a sequence, and loops are searched sequence against sequence, so the
// database is queried once per sequence instead of once per keyframe.
//
// Our reading (docs/loop_sequences.md has the reasoning):
//  * θ between keyframes a and b: R = R_cw_b · R_cw_a^T, θ = arccos((tr R − 1) / 2) (Eqs. 6–9), taken
//    between consecutive keyframes (option: against the sequence's first keyframe).
//  * trigger "rising-edge" (default, the paper's prose): with θ1 the previous step and θ2 the step to
//    the new keyframe, the current sequence closes and the new keyframe starts the next one only when
//    θ1 < θ_T and θ2 > θ_T (a turn starts); a sustained turn, a turn that ends (θ1 > θ_T, θ2 < θ_T)
//    and every other case keep adding to the current sequence.
//    trigger "level" (our first reading): every step with θ >= θ_T closes the sequence.
//  * In both: a sequence holding fewer than min_length (2) keyframes never closes (L_S < 2), and one
//    that would exceed L_T (15) keyframes always closes. So a sequence has 1..L_T keyframes.
//  * A sequence's BoW vector is the L1-normalised sum of its keyframes' L1-normalised vectors.
//  * A sequence with fewer than min_length (2) keyframes does not close on θ (short_sequences_grow);
//    shorter ones (only the last one, at the end of a run) are neither queried nor filed.
//  * The newly CLOSED sequence is the query (its vector is complete); detection therefore lags the
//    newest keyframe by at most L_T keyframes.
#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "stillpoint/common/config_reader.hpp"
#include "stillpoint/loop/bow_vector.hpp"
#include "stillpoint/loop/keyframe_database.hpp"
#include "stillpoint/map/types.hpp"

namespace sp::loop {

// Loop detection speaks of the map's keyframes; only the BoW database files plain entry numbers.
using KeyframeId = map::KeyframeId;

using SequenceId = std::uint64_t;

struct SequenceParams {
  double theta_t = 0.1;  // θ_T: a larger rotation closes the sequence [rad], (0, π]
  // What closes a sequence on θ: "rising-edge" (paper §III-B prose: θ1 < θ_T and θ2 > θ_T) or "level"
  // (every θ >= θ_T; our first reading, kept so both can be measured).
  std::string trigger = "rising-edge";
  int max_length = 15;          // L_T: keyframes per sequence at most [count], 1..1000
  int min_length = 2;           // shorter sequences never close a loop [count], 1..1000
  bool angle_to_first = false;  // measure θ against the sequence's first keyframe, not the previous one
  // "Sequences shorter than min_length never close", read literally: such a sequence takes the next
  // keyframe whatever θ is. Without it a fast turn leaves one-keyframe sequences that can never close a
  // loop, and a loop that starts or ends in a turn is lost (office_a_loop_walking, docs/loop_sequences.md).
  bool short_sequences_grow = true;
  // Candidates share >= ratio x the most shared words (the per-keyframe filter, own value here): a
  // sequence's vector pools up to L_T keyframes' words, so a 15-keyframe sequence shares far more words
  // with any query than a 2-keyframe one showing the same place; at 0.8 (and 0.5) the true loop of
  // office_a_loop_walking (a 2-keyframe sequence at the start) was filtered out, at 0.3 it ranks first.
  double min_common_ratio = 0.3;  // [-], (0, 1]
  // Consecutive query sequences a candidate group must persist [count], 1..20. 1: a sequence already
  // pools up to L_T keyframes of evidence, and each extra sequence delays a loop by up to L_T keyframes.
  int min_consistency = 1;
  int exclude_recent = 1;  // the last N filed sequences are never candidates [count], 0..100

  static SequenceParams from_yaml(const sp::ConfigReader& r);
  void validate() const;  // throws sp::Error
};

// Rotation angle between two camera orientations (world-to-camera rotations), in [0, π] rad.
double rotation_angle(const Eigen::Matrix3d& R_cw_a, const Eigen::Matrix3d& R_cw_b);

struct KeyframeSequence {
  SequenceId id = 0;                  // 0, 1, 2, ... in the order sequences start
  std::vector<KeyframeId> keyframes;  // in insertion order
  BowVector bow;                      // normalised sum of the keyframes' vectors
};

// Algorithm 1's segmentation, alone (no database): feed keyframes in order.
class SequenceSegmenter {
 public:
  explicit SequenceSegmenter(const SequenceParams& params);

  // Adds the next keyframe. Returns the sequence this keyframe closed, if it closed one; the
  // keyframe itself then starts the next sequence.
  // The vector is shared, not copied: the detector keeps the same one for re-ranking.
  std::optional<KeyframeSequence> add(KeyframeId id, const Eigen::Matrix3d& R_cw,
                                      std::shared_ptr<const BowVector> bow);
  std::optional<KeyframeSequence> add(KeyframeId id, const Eigen::Matrix3d& R_cw, const BowVector& bow) {
    return add(id, R_cw, std::make_shared<const BowVector>(bow));
  }
  // Closes the open sequence (end of the run); nullopt when it is empty.
  std::optional<KeyframeSequence> flush();

  [[nodiscard]] const std::vector<KeyframeId>& open_keyframes() const noexcept { return ids_; }
  [[nodiscard]] SequenceId open_id() const noexcept { return next_id_; }

 private:
  KeyframeSequence close();

  SequenceParams params_;
  SequenceId next_id_ = 0;
  std::vector<KeyframeId> ids_;
  std::vector<std::shared_ptr<const BowVector>> bows_;
  Eigen::Matrix3d first_R_ = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d last_R_ = Eigen::Matrix3d::Identity();
  std::optional<double> last_step_;  // θ1: the step that brought the newest keyframe (any sequence)
};

}  // namespace sp::loop
