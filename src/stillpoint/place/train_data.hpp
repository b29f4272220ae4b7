#pragma once
// Internal to sp_place (torch in the interface): the image store, descriptor cache, NetVLAD k-means
// initialisation and validation shared by triplet training (trainer.cpp) and feature distillation
// (distill.cpp).
#include <torch/torch.h>

#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "stillpoint/place/augment.hpp"
#include "stillpoint/place/distributed.hpp"
#include "stillpoint/place/model.hpp"
#include "stillpoint/place/retrieval.hpp"

namespace sp::place::detail {

// Normalised float batch (ImageNet mean/std, as image_to_tensor) from a uint8 (N,3,H,W) store.
torch::Tensor normalise(const torch::Tensor& u8);

// Every image resized to (h, w), RGB, uint8 (N,3,H,W).
torch::Tensor load_images(const std::vector<std::filesystem::path>& files, int h, int w, bool progress,
                          const char* what);

// Descriptors of every stored image, sharded over the ranks of `pg` (every rank gets all of them).
torch::Tensor describe_all(ParCNetVLAD& model, const torch::Tensor& store, int batch, ProcessGroup& pg);

// NetVLAD centroids and sharpness from k-means on the model's features of `images` random images.
void init_centroids(ParCNetVLAD& model, const torch::Tensor& store, int images, std::mt19937_64& rng);

// The --val sets: each scored as `vpr eval --dataset DIR` would (its own query/database split), all
// images in one uint8 store so that describing them reuses the sharded cache code.
struct ValData {
  struct Set {
    std::string dir;
    int64_t first = 0;  // row of its first query in the store; the database follows the queries
    int64_t queries = 0, database = 0;
    std::vector<std::vector<int>> ground_truth;
  };
  std::vector<Set> sets;
  torch::Tensor store;
};

ValData load_val(const std::vector<std::filesystem::path>& dirs, const PlaceRules& rules, int h, int w,
                 bool lead, bool progress);

// Recall@N pooled over the val sets (each query counts once), identical on every rank.
RecallResult evaluate_val(ParCNetVLAD& model, const ValData& v, ProcessGroup& pg);

// Augments a batch in place: row r of `batch` (uint8 N,3,H,W) with keys[r].
void augment_batch(torch::Tensor& batch, const AugmentOptions& o, const std::vector<AugmentKey>& keys);

// Sets the learning rate of every parameter group.
void set_lr(torch::optim::Optimizer& opt, double lr);

}  // namespace sp::place::detail
