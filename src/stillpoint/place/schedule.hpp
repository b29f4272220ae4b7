#pragma once
// When the learning rate changes and when training stops: pure functions of the step and the
// validation history, so a resumed or data-parallel run takes the same decisions (torch-free).
#include <cstdint>
#include <string>

namespace sp::place {

enum class LrScheduleKind { Constant, Cosine, Step };

// "constant" | "cosine" | "step"; throws sp::Error naming the choices.
LrScheduleKind parse_lr_schedule(const std::string& name);
std::string to_string(LrScheduleKind kind);

struct LrSchedule {
  LrScheduleKind kind = LrScheduleKind::Cosine;
  double warmup_epochs = 1;    // linear ramp from ~0 to the base rate over these epochs (0: none)
  double final_factor = 0.01;  // cosine: the rate at the last step, as a fraction of the base rate
  int step_epochs = 0;         // step: epochs between decays; 0: a third of the post-warm-up epochs
  double step_gamma = 0.1;     // step: factor per decay
};

// Throws sp::Error for a negative warm-up, a final factor outside [0, 1], a negative step_epochs or a
// gamma outside (0, 1].
void validate(const LrSchedule& s);

// Learning rate of optimiser step `step` (0-based, counted over the whole run, i.e. across epochs) when
// every epoch has `steps_per_epoch` steps and the run `epochs` epochs. Per step: the warm-up ramp and
// the cosine are smooth within an epoch, and the rate never exceeds base_lr. The step schedule decays
// every `step_epochs` epochs counted from the end of the warm-up, i.e. at the first step at or after
// warmup_epochs + n·step_epochs epochs: on epoch boundaries only when warmup_epochs is a whole number
// (a fractional warm-up, e.g. 0.5, moves every decay into the middle of an epoch). Depends on nothing
// else, so a run resumed after epoch e continues with step e·steps_per_epoch exactly.
[[nodiscard]] double learning_rate(const LrSchedule& s, double base_lr, std::int64_t step,
                                   std::int64_t steps_per_epoch, int epochs);

// Early stopping on a validation score (higher is better). Feed one score per epoch; `stop()` says
// whether `patience` epochs in a row have passed without a strict improvement (patience 0: never).
class EarlyStopping {
 public:
  explicit EarlyStopping(int patience) : patience_(patience) {}
  // Restores the state of a resumed run: the best score so far and the epoch that reached it.
  void restore(double best, int best_epoch) {
    best_ = best;
    best_epoch_ = best_epoch;
  }
  // Returns true when `score` is a new best (then the caller keeps this epoch's weights).
  bool update(int epoch, double score);
  [[nodiscard]] bool stop(int epoch) const {
    return patience_ > 0 && best_epoch_ > 0 && epoch - best_epoch_ >= patience_;
  }
  [[nodiscard]] double best() const { return best_; }
  [[nodiscard]] int best_epoch() const { return best_epoch_; }  // 0: no score yet

 private:
  int patience_;
  double best_ = -1;
  int best_epoch_ = 0;
};

}  // namespace sp::place
