#pragma once
// Training of ParC_NetVLAD on dynsynth `places` folders: triplet margin loss on squared L2 distances
// with hard negatives mined from a periodically refreshed descriptor cache (NetVLAD-style).
// Optionally data-parallel over several processes (libtorch's c10d, docs/place_recognition.md).
// Torch-free interface.
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "stillpoint/place/augment.hpp"
#include "stillpoint/place/dist_options.hpp"
#include "stillpoint/place/model_config.hpp"
#include "stillpoint/place/retrieval.hpp"
#include "stillpoint/place/schedule.hpp"

namespace sp::place {

struct TrainOptions {
  std::vector<std::filesystem::path> data;  // places folders, or folders of them
  std::filesystem::path out;                // final model file; checkpoints go to <out>.ckpt*
  ModelConfig model = ModelConfig::small();
  PlaceRules rules;
  int epochs = 8;                  // [1, 1000]
  double lr = 1e-3;                // base learning rate (>= 0; 0 leaves the weights as they are)
  LrSchedule lr_schedule;          // per-step: warm-up ramp, then constant, cosine or step decay
  std::string optimizer = "adam";  // adam | sgd (momentum 0.9)
  double margin = 0.1;             // on squared L2 distances
  int negatives = 5;               // hard negatives per query
  int negative_pool = 400;         // random negatives scored per query to pick the hardest from
  int queries_per_epoch = 320;     // sampled training queries per epoch (all ranks together)
  int batch = 4;                   // queries per step and rank (each brings 1 + 1 + negatives images)
  int refresh_every = 160;         // queries between descriptor-cache refreshes
  int kmeans_images = 200;         // images whose features initialise the NetVLAD centroids
  std::uint64_t seed = 1;          // torch::manual_seed and the mining RNG
  std::filesystem::path resume;    // checkpoint to continue from (empty = start fresh)
  // Model file to start from (e.g. `vpr distill`'s output): its architecture, weights and NetVLAD
  // centroids replace `model` and the k-means initialisation. Not with `resume`.
  std::filesystem::path init;
  // Applied to the images of each training batch (not to the mining cache nor to validation).
  AugmentOptions augment;
  // Places folders (or any `vpr eval` set) never trained on: Recall@1/5/10 after every epoch. With
  // them, the model written to `out` is the epoch with the best R@1, not the last.
  std::vector<std::filesystem::path> val;
  int patience = 0;      // stop when val R@1 has not improved for this many epochs (0: never)
  int threads = 2;       // libtorch intra-op threads
  bool progress = true;  // progress bar (rank 0 only)
  // Data parallelism: world_size processes each take `batch` queries of every step; gradients are
  // summed over all ranks and divided by the step's total triplet count. Rank 0 hosts the rendezvous
  // at master_addr:master_port and alone writes checkpoints and the model.
  DistOptions dist;
};

struct EpochStats {
  int epoch = 0;
  double loss = 0;    // mean triplet loss
  double active = 0;  // fraction of (query, negative) pairs inside the margin
  double seconds = 0;
  double rank_drift = 0;  // largest |weight − rank 0's| before the end-of-epoch sync (0: lockstep)
  double lr = 0;          // learning rate of the epoch's last step
  std::optional<RecallResult> val;  // on the --val sets (all queries pooled), when given
};

// Throws sp::Error for an option out of range (epochs, lr, batch, …, the schedule, the augmentation,
// patience) before any work; the CLI checks ranges too, this guards library callers.
void validate(const TrainOptions& o);

// Trains (or resumes) and writes the final model to options.out, and on rank 0 after every epoch the
// training log <out>.log.json / .log.csv and the curve <out>.curve.png (training_log.hpp). Returns the
// statistics of the epochs run now (a resumed run's earlier epochs stay in the log files only).
std::vector<EpochStats> train_model(const TrainOptions& options);

// Loads and resizes every image of the given places folders (shared by training and tests).
std::vector<PlaceImage> collect_places(const std::vector<std::filesystem::path>& dirs);

}  // namespace sp::place
