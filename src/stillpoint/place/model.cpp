#include "stillpoint/place/model.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "stillpoint/common/atomic_file.hpp"
#include "stillpoint/common/error.hpp"

namespace sp::place {

namespace F = torch::nn::functional;

// ---------------------------------------------------------------------------------------------

ChannelNormImpl::ChannelNormImpl(int channels) {
  norm = register_module("norm", torch::nn::LayerNorm(torch::nn::LayerNormOptions({channels}).eps(1e-6)));
}

torch::Tensor ChannelNormImpl::forward(const torch::Tensor& x) {
  return norm(x.permute({0, 2, 3, 1})).permute({0, 3, 1, 2});
}

// ---------------------------------------------------------------------------------------------

ParCOperatorImpl::ParCOperatorImpl(int channels, bool vertical_, int base_size, bool use_pe_)
    : vertical(vertical_), use_pe(use_pe_) {
  const std::vector<int64_t> kshape = vertical ? std::vector<int64_t>{channels, 1, base_size, 1}
                                               : std::vector<int64_t>{channels, 1, 1, base_size};
  // Same fan-in scaling as a conv of that kernel size.
  const double bound = 1.0 / std::sqrt(static_cast<double>(base_size));
  meta_kernel = register_parameter("meta_kernel", torch::empty(kshape).uniform_(-bound, bound));
  bias = register_parameter("bias", torch::empty({channels}).uniform_(-bound, bound));
  const std::vector<int64_t> pshape = vertical ? std::vector<int64_t>{1, channels, base_size, 1}
                                               : std::vector<int64_t>{1, channels, 1, base_size};
  pe = register_parameter("pe", torch::randn(pshape) * 0.02, use_pe);
}

static torch::Tensor resize_along(const torch::Tensor& t, bool vertical, int64_t length) {
  const int64_t cur = vertical ? t.size(2) : t.size(3);
  if (cur == length) return t;
  const std::vector<int64_t> size =
      vertical ? std::vector<int64_t>{length, 1} : std::vector<int64_t>{1, length};
  return F::interpolate(t, F::InterpolateFuncOptions().size(size).mode(torch::kBilinear).align_corners(true));
}

torch::Tensor ParCOperatorImpl::instance_kernel(int64_t length) const {
  return resize_along(meta_kernel, vertical, length);
}

torch::Tensor ParCOperatorImpl::instance_pe(int64_t length) const {
  return resize_along(pe, vertical, length);
}

torch::Tensor ParCOperatorImpl::forward(const torch::Tensor& x) {
  const int64_t length = vertical ? x.size(2) : x.size(3);
  torch::Tensor y = use_pe ? x + instance_pe(length) : x;
  const torch::Tensor kernel = instance_kernel(length);
  // Circular padding: append the first L-1 entries so output i sees inputs i..i+L-1 (mod L).
  const int dim = vertical ? 2 : 3;
  y = torch::cat({y, y.narrow(dim, 0, length - 1)}, dim);
  return F::conv2d(y, kernel, F::Conv2dFuncOptions().bias(bias).groups(x.size(1)));
}

// ---------------------------------------------------------------------------------------------

ConvNeXtBlockImpl::ConvNeXtBlockImpl(int channels, bool parc_, int base_h, int base_w, double drop_path_,
                                     double ls_init)
    : parc(parc_), drop_path(drop_path_) {
  if (parc) {
    if (channels % 2 != 0) throw sp::Error("ParC block needs an even channel count");
    parc_h = register_module("parc_h", ParCOperator(channels / 2, true, base_h));
    parc_w = register_module("parc_w", ParCOperator(channels / 2, false, base_w));
  } else {
    dwconv = register_module(
        "dwconv",
        torch::nn::Conv2d(torch::nn::Conv2dOptions(channels, channels, 7).padding(3).groups(channels)));
  }
  norm = register_module("norm", torch::nn::LayerNorm(torch::nn::LayerNormOptions({channels}).eps(1e-6)));
  pw1 = register_module("pw1", torch::nn::Linear(channels, 4 * channels));
  pw2 = register_module("pw2", torch::nn::Linear(4 * channels, channels));
  gamma = register_parameter("gamma", torch::full({channels}, ls_init));
}

torch::Tensor ConvNeXtBlockImpl::forward(const torch::Tensor& x) {
  torch::Tensor y;
  if (parc) {
    auto halves = x.chunk(2, 1);
    y = torch::cat({parc_h(halves[0]), parc_w(halves[1])}, 1);
  } else {
    y = dwconv(x);
  }
  y = y.permute({0, 2, 3, 1});
  y = pw2(F::gelu(pw1(norm(y))));
  y = (gamma * y).permute({0, 3, 1, 2});
  if (is_training() && drop_path > 0.0) {
    const double keep = 1.0 - drop_path;
    auto mask = torch::empty({x.size(0), 1, 1, 1}, x.options()).bernoulli_(keep);
    y = y * mask / keep;
  }
  return x + y;
}

// ---------------------------------------------------------------------------------------------

BackboneImpl::BackboneImpl(const ModelConfig& cfg) {
  downsample = register_module("downsample", torch::nn::ModuleList());
  stages = register_module("stages", torch::nn::ModuleList());
  torch::nn::Sequential stem(torch::nn::Conv2d(torch::nn::Conv2dOptions(3, cfg.widths[0], 4).stride(4)),
                             ChannelNorm(cfg.widths[0]));
  downsample->push_back(stem);
  for (int i = 1; i < 4; ++i) {
    downsample->push_back(torch::nn::Sequential(
        ChannelNorm(cfg.widths[i - 1]),
        torch::nn::Conv2d(torch::nn::Conv2dOptions(cfg.widths[i - 1], cfg.widths[i], 2).stride(2))));
  }
  const int total = cfg.depths[0] + cfg.depths[1] + cfg.depths[2] + cfg.depths[3];
  int index = 0;
  // Feature-map size at the configured input: the ParC meta-kernels' base length.
  int fh = cfg.input_height / 4, fw = cfg.input_width / 4;
  for (int s = 0; s < 4; ++s) {
    if (s > 0) fh /= 2, fw /= 2;
    // Paper §IV-C: ParC in the last three blocks of stage 3 and the last block of stage 4.
    const int parc_count = !cfg.parc ? 0 : s == 2 ? 3 : s == 3 ? 1 : 0;
    torch::nn::Sequential stage;
    for (int b = 0; b < cfg.depths[s]; ++b, ++index) {
      const double dp = total > 1 ? cfg.drop_path * index / (total - 1) : 0.0;
      const bool parc = b >= cfg.depths[s] - parc_count;
      stage->push_back(
          ConvNeXtBlock(cfg.widths[s], parc, std::max(fh, 1), std::max(fw, 1), dp, cfg.layer_scale_init));
    }
    stages->push_back(stage);
  }
}

std::vector<torch::Tensor> BackboneImpl::stage_outputs(torch::Tensor x) {
  std::vector<torch::Tensor> out;
  for (size_t i = 0; i < 4; ++i) {
    x = downsample[i]->as<torch::nn::Sequential>()->forward(x);
    if (i == 0) out.push_back(x);
    x = stages[i]->as<torch::nn::Sequential>()->forward(x);
    out.push_back(x);
  }
  return out;
}

torch::Tensor BackboneImpl::forward(torch::Tensor x) { return stage_outputs(std::move(x)).back(); }

// ---------------------------------------------------------------------------------------------

CBAMImpl::CBAMImpl(int channels, int reduction) {
  const int hidden = std::max(1, channels / reduction);
  mlp = register_module(
      "mlp", torch::nn::Sequential(torch::nn::Conv2d(torch::nn::Conv2dOptions(channels, hidden, 1)),
                                   torch::nn::ReLU(),
                                   torch::nn::Conv2d(torch::nn::Conv2dOptions(hidden, channels, 1))));
  spatial = register_module("spatial", torch::nn::Conv2d(torch::nn::Conv2dOptions(2, 1, 7).padding(3)));
}

std::tuple<torch::Tensor, torch::Tensor, torch::Tensor> CBAMImpl::forward_with_weights(
    const torch::Tensor& x) {
  const auto avg = x.mean({2, 3}, true);
  const auto mx = x.amax({2, 3}, true);
  const auto ca = torch::sigmoid(mlp->forward(avg) + mlp->forward(mx));
  const auto y = x * ca;
  const auto pooled = torch::cat({y.mean(1, true), y.amax(1, true)}, 1);
  const auto sa = torch::sigmoid(spatial(pooled));
  return {y * sa, ca, sa};
}

torch::Tensor CBAMImpl::forward(const torch::Tensor& x) { return std::get<0>(forward_with_weights(x)); }

// ---------------------------------------------------------------------------------------------

NetVLADImpl::NetVLADImpl(int clusters_, int dim_) : clusters(clusters_), dim(dim_) {
  assign = register_module("assign", torch::nn::Conv2d(torch::nn::Conv2dOptions(dim, clusters, 1)));
  centroids = register_parameter("centroids", torch::rand({clusters, dim}));
}

void NetVLADImpl::init_from_centroids(const torch::Tensor& centres, double alpha) {
  torch::NoGradGuard guard;
  centroids.copy_(centres);
  // Softmax over -alpha·||x - c||² = 2·alpha·x·c - alpha·||c||² (+ a term common to all clusters).
  assign->weight.copy_((2.0 * alpha * centres).view({clusters, dim, 1, 1}));
  assign->bias.copy_(-alpha * centres.pow(2).sum(1));
}

torch::Tensor NetVLADImpl::forward(const torch::Tensor& x_in) {
  const int64_t n = x_in.size(0);
  const auto x = F::normalize(x_in, F::NormalizeFuncOptions().p(2).dim(1));
  const auto a = torch::softmax(assign(x).view({n, clusters, -1}), 1);  // (N,K,HW)
  const auto flat = x.view({n, dim, -1});                               // (N,D,HW)
  // Σ_i a_k(i)·(x_i − c_k) = a·xᵀ − (Σ_i a_k(i))·c_k
  auto vlad = torch::bmm(a, flat.transpose(1, 2)) - a.sum(2).unsqueeze(2) * centroids.unsqueeze(0);
  vlad = F::normalize(vlad, F::NormalizeFuncOptions().p(2).dim(2));  // intra-normalisation
  return F::normalize(vlad.reshape({n, -1}), F::NormalizeFuncOptions().p(2).dim(1));
}

// ---------------------------------------------------------------------------------------------

ParCNetVLADImpl::ParCNetVLADImpl(const ModelConfig& c) : cfg(c) {
  backbone = register_module("backbone", Backbone(cfg));
  if (cfg.cbam) cbam = register_module("cbam", CBAM(cfg.widths[3]));
  vlad = register_module("vlad", NetVLAD(cfg.clusters, cfg.widths[3]));
}

torch::Tensor ParCNetVLADImpl::features(const torch::Tensor& x) {
  auto f = backbone(x);
  return cfg.cbam ? cbam(f) : f;
}

torch::Tensor ParCNetVLADImpl::forward(const torch::Tensor& x) { return vlad(features(x)); }

// ---------------------------------------------------------------------------------------------

torch::Tensor image_to_tensor(const cv::Mat& bgr, int height, int width) {
  if (bgr.empty() || bgr.type() != CV_8UC3) throw sp::Error("place: expected a non-empty 8-bit BGR image");
  cv::Mat resized, rgb;
  if (bgr.rows != height || bgr.cols != width) {
    cv::resize(bgr, resized, cv::Size(width, height), 0, 0, cv::INTER_AREA);
  } else {
    resized = bgr;
  }
  cv::cvtColor(resized, rgb, cv::COLOR_BGR2RGB);
  auto t = torch::from_blob(rgb.data, {height, width, 3}, torch::kUInt8).clone();
  t = t.permute({2, 0, 1}).to(torch::kFloat32).div_(255.0);
  const auto mean = torch::tensor({0.485f, 0.456f, 0.406f}).view({3, 1, 1});
  const auto std = torch::tensor({0.229f, 0.224f, 0.225f}).view({3, 1, 1});
  return ((t - mean) / std).unsqueeze(0);
}

void save_model(ParCNetVLAD& model, const std::filesystem::path& file) {
  torch::serialize::OutputArchive archive;
  model->save(archive);
  const auto& c = model->cfg;
  const std::vector<int64_t> meta = {
      1,  // format version
      c.depths[0], c.depths[1],    c.depths[2],    c.depths[3], c.widths[0],    c.widths[1],  c.widths[2],
      c.widths[3], c.parc ? 1 : 0, c.cbam ? 1 : 0, c.clusters,  c.input_height, c.input_width};
  archive.write("sp_model_config", torch::tensor(meta, torch::kInt64));
  if (file.has_parent_path()) std::filesystem::create_directories(file.parent_path());
  std::ostringstream bytes;
  archive.save_to(bytes);
  write_file_atomically(file, bytes.str());
}

ParCNetVLAD load_model(const std::filesystem::path& file) {
  if (!std::filesystem::exists(file)) throw sp::InputError(file.string(), 0, "model file not found");
  torch::serialize::InputArchive archive;
  torch::Tensor meta;
  try {
    archive.load_from(file.string());
    archive.read("sp_model_config", meta);
  } catch (const c10::Error& e) {
    throw sp::InputError(file.string(), 0,
                         std::string("not a ParC_NetVLAD model: ") + e.what_without_backtrace());
  }
  if (meta.numel() != 14 || meta[0].item<int64_t>() != 1) {
    throw sp::InputError(file.string(), 0, "unsupported model format version");
  }
  ModelConfig c;
  const auto v = [&](int i) { return static_cast<int>(meta[i].item<int64_t>()); };
  for (int i = 0; i < 4; ++i) c.depths[i] = v(1 + i), c.widths[i] = v(5 + i);
  c.parc = v(9) != 0;
  c.cbam = v(10) != 0;
  c.clusters = v(11);
  c.input_height = v(12);
  c.input_width = v(13);
  ParCNetVLAD model(c);
  try {
    model->load(archive);
  } catch (const c10::Error& e) {
    throw sp::InputError(file.string(), 0, std::string("cannot load weights: ") + e.what_without_backtrace());
  }
  model->eval();
  return model;
}

torch::Tensor triplet_loss(const torch::Tensor& q, const torch::Tensor& p, const torch::Tensor& n,
                           double margin) {
  const auto dp = (q - p).pow(2).sum(1, true);         // (B,1)
  const auto dn = (q.unsqueeze(1) - n).pow(2).sum(2);  // (B,M)
  return torch::clamp_min(dp + margin - dn, 0.0).sum(1).mean();
}

}  // namespace sp::place
