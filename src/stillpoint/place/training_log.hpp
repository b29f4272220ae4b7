#pragma once
// The per-epoch training log: <out>.log.json (array of {epoch, loss, active, lr, seconds, val_r1,
// val_r5, val_r10}; val_* null without validation), <out>.log.csv (the same columns, empty cells for
// null) and <out>.curve.png (loss and validation R@1 against the epoch, drawn with OpenCV).
#include <filesystem>
#include <opencv2/core.hpp>
#include <vector>

#include "stillpoint/place/trainer.hpp"

namespace sp::place {

// Writes all three files (overwriting); `out` is the model path they are named after.
void write_training_log(const std::filesystem::path& out, const std::vector<EpochStats>& rows);

// Rows of an existing <out>.log.json (for a resumed run); empty when the file does not exist. A null
// loss, active, lr or seconds (how the JSON holds a NaN or infinite value) reads back as NaN.
// Throws sp::InputError when it exists but is not a training log.
std::vector<EpochStats> read_training_log(const std::filesystem::path& out);

// The curve image: loss on the left axis, val R@1 (0–1) on the right, epochs along x, with a legend.
cv::Mat draw_training_curve(const std::vector<EpochStats>& rows, int width = 800, int height = 480);

}  // namespace sp::place
