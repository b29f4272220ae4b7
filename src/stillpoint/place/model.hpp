#pragma once
// ParC_NetVLAD network (internal to sp_place: includes libtorch; other modules use descriptor.hpp).
// ConvNeXt backbone whose last blocks use position-aware circular convolutions (ParC), CBAM
// attention on the final feature map, and a NetVLAD head.
#include <torch/torch.h>

#include <array>
#include <filesystem>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "stillpoint/place/model_config.hpp"

namespace sp::place {

// LayerNorm over the channel axis of an NCHW tensor.
struct ChannelNormImpl : torch::nn::Module {
  explicit ChannelNormImpl(int channels);
  torch::Tensor forward(const torch::Tensor& x);
  torch::nn::LayerNorm norm{nullptr};
};
TORCH_MODULE(ChannelNorm);

// Position-aware circular convolution along one axis (ParC-Net): a learnable meta-kernel and
// positional embedding of a base length, both bilinearly resized to the feature map's length at run
// time, a depthwise global kernel as long as the feature map, and circular padding.
struct ParCOperatorImpl : torch::nn::Module {
  // vertical = true: kernel H×1 (ParC-H mixes along rows' index, i.e. the height axis).
  ParCOperatorImpl(int channels, bool vertical, int base_size, bool use_pe = true);
  torch::Tensor forward(const torch::Tensor& x);
  // Kernel (C, L) and positional embedding (C, L) resized to length L.
  [[nodiscard]] torch::Tensor instance_kernel(int64_t length) const;
  [[nodiscard]] torch::Tensor instance_pe(int64_t length) const;

  bool vertical;
  bool use_pe;
  torch::Tensor meta_kernel;  // (C, 1, base, 1) or (C, 1, 1, base)
  torch::Tensor bias;         // (C)
  torch::Tensor pe;           // (1, C, base, 1) or (1, C, 1, base)
};
TORCH_MODULE(ParCOperator);

// ConvNeXt block: token mixer (7×7 depthwise, or ParC-H ‖ ParC-V on half the channels each) → LN →
// 1×1 (4×) → GELU → 1×1 → layer scale → drop path → residual.
struct ConvNeXtBlockImpl : torch::nn::Module {
  ConvNeXtBlockImpl(int channels, bool parc, int base_h, int base_w, double drop_path, double ls_init);
  torch::Tensor forward(const torch::Tensor& x);

  bool parc;
  double drop_path;
  torch::nn::Conv2d dwconv{nullptr};
  ParCOperator parc_h{nullptr}, parc_w{nullptr};
  torch::nn::LayerNorm norm{nullptr};
  torch::nn::Linear pw1{nullptr}, pw2{nullptr};
  torch::Tensor gamma;
};
TORCH_MODULE(ConvNeXtBlock);

// ConvNeXt backbone without pooling, final norm and classifier: NCHW image → (N, widths[3], H/32, W/32).
struct BackboneImpl : torch::nn::Module {
  explicit BackboneImpl(const ModelConfig& cfg);
  torch::Tensor forward(torch::Tensor x);
  // Output of the stem and of each stage (for shape tests).
  std::vector<torch::Tensor> stage_outputs(torch::Tensor x);

  torch::nn::ModuleList downsample{nullptr};  // [stem(conv+LN), LN+conv, LN+conv, LN+conv]
  torch::nn::ModuleList stages{nullptr};
};
TORCH_MODULE(Backbone);

// CBAM: channel attention (shared MLP over avg/max pooling) then spatial attention (7×7 conv over
// channel mean/max). Shape unchanged.
struct CBAMImpl : torch::nn::Module {
  explicit CBAMImpl(int channels, int reduction = 16);
  torch::Tensor forward(const torch::Tensor& x);
  // Returns (output, channel weights (N,C,1,1), spatial weights (N,1,H,W)).
  std::tuple<torch::Tensor, torch::Tensor, torch::Tensor> forward_with_weights(const torch::Tensor& x);

  torch::nn::Sequential mlp{nullptr};
  torch::nn::Conv2d spatial{nullptr};
};
TORCH_MODULE(CBAM);

// NetVLAD: soft assignment by 1×1 conv + softmax over K, residuals to centroids, intra-normalisation,
// flatten, L2 normalisation → (N, K·D).
struct NetVLADImpl : torch::nn::Module {
  NetVLADImpl(int clusters, int dim);
  torch::Tensor forward(const torch::Tensor& x);
  // Sets centroids and the assignment conv from k-means centres (K, D) of L2-normalised features.
  void init_from_centroids(const torch::Tensor& centres, double alpha);

  int clusters, dim;
  torch::nn::Conv2d assign{nullptr};
  torch::Tensor centroids;  // (K, D)
};
TORCH_MODULE(NetVLAD);

struct ParCNetVLADImpl : torch::nn::Module {
  explicit ParCNetVLADImpl(const ModelConfig& cfg);
  // Normalised RGB batch (N,3,H,W) → descriptors (N, K·D).
  torch::Tensor forward(const torch::Tensor& x);
  // Backbone (+CBAM) features before NetVLAD.
  torch::Tensor features(const torch::Tensor& x);

  ModelConfig cfg;
  Backbone backbone{nullptr};
  CBAM cbam{nullptr};
  NetVLAD vlad{nullptr};
};
TORCH_MODULE(ParCNetVLAD);

// BGR 8-bit image → normalised (1,3,H,W) float tensor at the model's input size (ImageNet mean/std).
torch::Tensor image_to_tensor(const cv::Mat& bgr, int height, int width);

// Model file: a torch archive with the weights plus the configuration. Written whole or not at all (a
// kill while saving leaves the previous file), its folder created if needed.
void save_model(ParCNetVLAD& model, const std::filesystem::path& file);
ParCNetVLAD load_model(const std::filesystem::path& file);

// Triplet margin loss on squared L2 distances, summed over negatives, mean over the batch:
// q (B,D), p (B,D), n (B,M,D).
torch::Tensor triplet_loss(const torch::Tensor& q, const torch::Tensor& p, const torch::Tensor& n,
                           double margin);

}  // namespace sp::place
