#pragma once
// Feature distillation: the ParC_NetVLAD backbone learns to reproduce, through a 1×1 projection per
// level, the local features of a pretrained teacher network (by default the COCO-trained YOLOX-nano
// detector the project ships), then NetVLAD is initialised by k-means on the distilled features.
// This stands in for the ImageNet initialisation the paper starts from, which cannot be downloaded
// here (docs/place_recognition.md, "Distilled initialisation"). Torch-free interface.
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "stillpoint/place/augment.hpp"
#include "stillpoint/place/model_config.hpp"
#include "stillpoint/place/retrieval.hpp"

namespace sp::place {

struct DistillOptions {
  std::vector<std::filesystem::path> data;  // places folders (or folders of them): training images
  std::filesystem::path teacher;            // ONNX network readable by OpenCV's dnn module
  // Teacher layers matched to the student's stride-16 map (backbone stage 3) and to the NetVLAD
  // input (stage 4, after CBAM), each area-pooled to the student's grid. Both default to YOLOX-nano's
  // dark4 output (stride 16): k-means NetVLAD on it pooled to 7×10 retrieves far better than on
  // dark5 (docs/place_recognition.md). An empty name drops that level.
  std::string teacher_mid = "onnx_node!Mul_161";
  std::string teacher_top = "onnx_node!Mul_161";
  int teacher_size = 416;      // square teacher input (YOLOX-nano's ONNX is fixed at 416×416)
  double top_weight = 1.0;     // weight of the stage-4 loss relative to the stage-3 loss
  bool center_targets = true;  // subtract the teacher's per-channel mean before the cosine
  std::filesystem::path out;   // model file written (NetVLAD initialised by k-means)
  ModelConfig model = ModelConfig::small();
  int steps = 1200;       // optimiser steps (the shipped model: 1200, docs/place_recognition.md)
  int batch = 16;         // images per step
  double lr = 3e-3;       // Adam, linear warm-up over the first 5 % of steps, then cosine to 1 %
  int max_images = 4000;  // images whose teacher features are cached, evenly spread (0: all)
  int kmeans_images = 200;
  AugmentOptions augment;  // photometric only: crop_max is forced to 0 so features stay aligned
  std::vector<std::filesystem::path> val;  // optional: Recall@N of the result (and every eval_every)
  int eval_every = 0;                      // steps between val evaluations (0: only at the end)
  PlaceRules rules;
  std::uint64_t seed = 1;
  int threads = 2;
  bool progress = true;
};

struct DistillStats {
  int steps = 0;
  double first_loss = 0;  // mean over the first min(50, steps / 5) steps (1 − cosine, weighted sum of levels)
  double last_loss = 0;             // mean over as many last steps
  double seconds = 0;               // teacher features included
  std::optional<RecallResult> val;  // of the written model, when options.val is given
};

// Throws sp::Error for an option out of range, before any work.
void validate(const DistillOptions& o);

// Distils, initialises NetVLAD by k-means and writes options.out. The teacher file and layers are
// checked first (sp::InputError naming the file).
DistillStats distill_model(const DistillOptions& options);

}  // namespace sp::place
