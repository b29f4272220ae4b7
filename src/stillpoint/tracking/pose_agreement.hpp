#pragma once
// Relocalisation's guard against ambiguous views (docs/robustness.md "Ambiguous views"): several
// candidate keyframes may each locate a lost frame with as much support, at places tens of
// centimetres apart, when all the frame shows is a repeated texture (a patterned wall seen between
// people). The first pose found is taken only once `needed` further candidates that locate the frame
// put it within the step limits of it; one that puts it elsewhere makes the frame ambiguous.
#include <optional>

#include "stillpoint/geometry/lie.hpp"
#include "stillpoint/tracking/pose_guard.hpp"

namespace sp::track {

class PoseAgreement {
 public:
  enum class Verdict { Undecided, Agreed, Ambiguous };

  // needed 0: the first pose is agreed at once.
  PoseAgreement(int needed, double max_translation_m, double max_rotation_deg)
      : needed_(needed), max_translation_m_(max_translation_m), max_rotation_deg_(max_rotation_deg) {}

  // One more candidate's pose of the frame, in candidate order. Once Agreed or Ambiguous the verdict
  // stays.
  Verdict add(const geo::SE3& T_cw);
  // The candidates ran out: a first pose that no candidate contradicted is taken.
  [[nodiscard]] Verdict finish() const;
  // How far the contradicting pose lay from the first (when Ambiguous).
  [[nodiscard]] const PoseDeviation& conflict() const { return conflict_; }

 private:
  int needed_;
  double max_translation_m_, max_rotation_deg_;
  std::optional<geo::SE3> first_;
  int agreeing_ = 0;
  Verdict verdict_ = Verdict::Undecided;
  PoseDeviation conflict_;
};

}  // namespace sp::track
