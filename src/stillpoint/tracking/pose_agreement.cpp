#include "stillpoint/tracking/pose_agreement.hpp"

namespace sp::track {

PoseAgreement::Verdict PoseAgreement::add(const geo::SE3& T_cw) {
  if (verdict_ != Verdict::Undecided) return verdict_;
  if (!first_) {
    first_ = T_cw;
  } else {
    const PoseDeviation d = pose_deviation(T_cw, *first_);
    if (!d.within(max_translation_m_, max_rotation_deg_)) {
      conflict_ = d;
      return verdict_ = Verdict::Ambiguous;
    }
    ++agreeing_;
  }
  if (agreeing_ >= needed_) verdict_ = Verdict::Agreed;
  return verdict_;
}

PoseAgreement::Verdict PoseAgreement::finish() const {
  if (verdict_ == Verdict::Undecided && first_) return Verdict::Agreed;
  return verdict_;
}

}  // namespace sp::track
