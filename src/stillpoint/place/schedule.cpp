#include "stillpoint/place/schedule.hpp"

#include <algorithm>
#include <cmath>

#include "stillpoint/common/error.hpp"

namespace sp::place {

LrScheduleKind parse_lr_schedule(const std::string& name) {
  if (name == "constant") return LrScheduleKind::Constant;
  if (name == "cosine") return LrScheduleKind::Cosine;
  if (name == "step") return LrScheduleKind::Step;
  throw sp::Error("learning-rate schedule must be constant, cosine or step, not '" + name + "'");
}

std::string to_string(LrScheduleKind kind) {
  switch (kind) {
    case LrScheduleKind::Constant:
      return "constant";
    case LrScheduleKind::Cosine:
      return "cosine";
    case LrScheduleKind::Step:
      return "step";
  }
  return "?";
}

void validate(const LrSchedule& s) {
  if (!(s.warmup_epochs >= 0 && s.warmup_epochs <= 1000))
    throw sp::Error("warm-up epochs must be in [0, 1000], not " + std::to_string(s.warmup_epochs));
  if (!(s.final_factor >= 0 && s.final_factor <= 1))
    throw sp::Error("the cosine's final factor must be in [0, 1], not " + std::to_string(s.final_factor));
  if (s.step_epochs < 0) throw sp::Error("lr step epochs must be >= 0, not " + std::to_string(s.step_epochs));
  if (!(s.step_gamma > 0 && s.step_gamma <= 1))
    throw sp::Error("lr step gamma must be in (0, 1], not " + std::to_string(s.step_gamma));
}

double learning_rate(const LrSchedule& s, double base_lr, std::int64_t step, std::int64_t steps_per_epoch,
                     int epochs) {
  steps_per_epoch = std::max<std::int64_t>(1, steps_per_epoch);
  const double spe = static_cast<double>(steps_per_epoch);
  const double total = spe * std::max(1, epochs);
  const double warm = s.warmup_epochs * spe;
  const double k = static_cast<double>(step);
  // (k + 1) / warm: the first step already moves (a zero rate would waste it), the last reaches base.
  // Capped at 1: when the warm-up is not a whole number of steps (0.5 epochs of 3 steps), the last
  // warm-up step has k + 1 > warm and would otherwise overshoot the base rate.
  if (k < warm) return base_lr * std::min(1.0, (k + 1) / warm);
  const double after = k - warm;  // steps since the warm-up ended
  const double span = std::max(1.0, total - warm);
  switch (s.kind) {
    case LrScheduleKind::Constant:
      return base_lr;
    case LrScheduleKind::Cosine: {
      const double p = std::clamp(after / span, 0.0, 1.0);
      return base_lr * (s.final_factor + (1 - s.final_factor) * 0.5 * (1 + std::cos(M_PI * p)));
    }
    case LrScheduleKind::Step: {
      const double every = s.step_epochs > 0 ? s.step_epochs : std::max(1.0, std::round(span / spe / 3));
      return base_lr * std::pow(s.step_gamma, std::floor(after / spe / every));
    }
  }
  return base_lr;
}

bool EarlyStopping::update(int epoch, double score) {
  if (best_epoch_ > 0 && !(score > best_)) return false;
  best_ = score;
  best_epoch_ = epoch;
  return true;
}

}  // namespace sp::place
