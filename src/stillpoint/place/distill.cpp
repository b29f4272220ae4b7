#include "stillpoint/place/distill.hpp"

#include <ATen/Parallel.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <cmath>
#include <opencv2/core.hpp>
#include <opencv2/dnn.hpp>
#include <opencv2/imgcodecs.hpp>
#include <random>

#include "stillpoint/common/error.hpp"
#include "stillpoint/common/progress_bar.hpp"
#include "stillpoint/place/distributed.hpp"
#include "stillpoint/place/model.hpp"
#include "stillpoint/place/schedule.hpp"
#include "stillpoint/place/train_data.hpp"
#include "stillpoint/place/trainer.hpp"

namespace sp::place {

namespace fs = std::filesystem;
namespace F = torch::nn::functional;
using namespace detail;

void validate(const DistillOptions& o) {
  const auto need = [](bool ok, const std::string& what) {
    if (!ok) throw sp::Error("vpr distill: " + what);
  };
  need(!o.data.empty(), "no --data folder");
  need(!o.out.empty(), "no --out file");
  need(!o.teacher.empty(), "no --teacher network");
  need(!o.teacher_mid.empty() || (!o.teacher_top.empty() && o.top_weight > 0),
       "nothing to distil: give a stage-3 teacher layer or a stage-4 layer with a positive weight");
  need(o.teacher_size >= 32 && o.teacher_size <= 4096,
       fmt::format("teacher input must be in [32, 4096] px, not {}", o.teacher_size));
  need(std::isfinite(o.top_weight) && o.top_weight >= 0, "top-weight must be >= 0");
  need(o.steps >= 1, fmt::format("steps must be >= 1, not {}", o.steps));
  need(o.batch >= 1, fmt::format("batch must be >= 1, not {}", o.batch));
  need(std::isfinite(o.lr) && o.lr >= 0 && o.lr <= 1, fmt::format("lr must be in [0, 1], not {}", o.lr));
  need(o.max_images >= 0, "max-images must be >= 0");
  need(o.kmeans_images >= 1, "kmeans-images must be >= 1");
  need(o.eval_every >= 0, "eval-every must be >= 0");
  need(o.threads >= 1, "threads must be >= 1");
  validate(o.augment);
}

namespace {

// The teacher network and the layers read from it, as (1, C, H, W) float tensors.
class Teacher {
 public:
  Teacher(const fs::path& file, std::vector<std::string> layers, int size)
      : layers_(std::move(layers)), size_(size) {
    if (!fs::exists(file)) throw sp::InputError(file.string(), 0, "teacher network not found");
    try {
      net_ = cv::dnn::readNet(file.string());
    } catch (const cv::Exception& e) {
      throw sp::InputError(file.string(), 0, std::string("cannot read the teacher network: ") + e.what());
    }
    if (net_.empty()) throw sp::InputError(file.string(), 0, "cannot read the teacher network");
    for (const auto& l : layers_)
      if (net_.getLayerId(l) < 0)
        throw sp::InputError(file.string(), 0, "the teacher has no layer '" + l + "'");
  }

  std::vector<torch::Tensor> features(const cv::Mat& bgr) {
    // YOLOX's ONNX export takes BGR 0–255 without mean/std; other teachers may need their own input.
    const cv::Mat blob = cv::dnn::blobFromImage(bgr, 1.0, cv::Size(size_, size_), cv::Scalar(), false, false);
    net_.setInput(blob);
    std::vector<cv::Mat> outs;
    net_.forward(outs, layers_);
    std::vector<torch::Tensor> t;
    for (auto& m : outs) {
      if (m.dims != 4) throw sp::Error("vpr distill: teacher layer output is not (1, C, H, W)");
      t.push_back(torch::from_blob(m.ptr<float>(), {1, m.size[1], m.size[2], m.size[3]}).clone());
    }
    return t;
  }

 private:
  cv::dnn::Net net_;
  std::vector<std::string> layers_;
  int size_;
};

// Per-location cosine distance, averaged: student (N,C,H,W) already projected, teacher unit vectors.
torch::Tensor cosine_loss(const torch::Tensor& student, const torch::Tensor& teacher_unit) {
  const auto s = F::normalize(student, F::NormalizeFuncOptions().dim(1));
  return (1 - (s * teacher_unit).sum(1)).mean();
}

// One matched pair: a student map (backbone stage 3, or stage 4 after CBAM: the NetVLAD input) and
// the teacher layer pooled onto its grid.
struct Level {
  int stage = 3;
  int teacher_slot = 0;
  double weight = 1;
  torch::Tensor targets;  // (N, Ct, h, w) unit vectors, half precision
  torch::nn::Conv2d proj{nullptr};
};

// The student's map for a level from the backbone's stage outputs.
torch::Tensor student_map(ParCNetVLAD& model, const std::vector<torch::Tensor>& stages, int stage) {
  if (stage == 4 && model->cfg.cbam) return model->cbam(stages[4]);
  return stages[static_cast<size_t>(stage)];
}

double mean(const std::vector<double>& v, size_t first, size_t count) {
  double m = 0;
  for (size_t k = first; k < first + count; ++k) m += v[k];
  return m / static_cast<double>(count);
}

}  // namespace

DistillStats distill_model(const DistillOptions& o) {
  validate(o);
  const auto t0 = std::chrono::steady_clock::now();
  at::set_num_threads(o.threads);
  cv::setNumThreads(o.threads);
  torch::manual_seed(o.seed);
  std::mt19937_64 rng(o.seed);

  std::vector<std::string> layers;
  std::vector<Level> levels;
  if (!o.teacher_mid.empty()) {
    levels.push_back({3, 0, 1.0, {}, nullptr});
    layers.push_back(o.teacher_mid);
  }
  if (!o.teacher_top.empty() && o.top_weight > 0) {
    // Both levels may read the same teacher layer (pooled to two grids): forward it once.
    const bool shared = !layers.empty() && o.teacher_top == o.teacher_mid;
    if (!shared) layers.push_back(o.teacher_top);
    levels.push_back({4, static_cast<int>(layers.size()) - 1, o.top_weight, {}, nullptr});
  }
  Teacher teacher(o.teacher, layers, o.teacher_size);

  const auto all = collect_places(o.data);
  std::vector<fs::path> files;
  const size_t step =
      o.max_images > 0 ? std::max<size_t>(1, all.size() / static_cast<size_t>(o.max_images)) : 1;
  for (size_t i = 0;
       i < all.size() && (o.max_images == 0 || files.size() < static_cast<size_t>(o.max_images)); i += step)
    files.push_back(all[i].file);
  if (files.empty()) throw sp::Error("vpr distill: no training image");

  ParCNetVLAD model(o.model);
  const int h = model->cfg.input_height, w = model->cfg.input_width;
  spdlog::info("distil: {} images, model {}", files.size(), model->cfg.summary());
  const auto store = load_images(files, h, w, o.progress, "loading images");

  // The student's map sizes at its input size fix the grid each teacher map is pooled to.
  std::vector<torch::Tensor> shapes;
  {
    torch::NoGradGuard g;
    model->eval();
    shapes = model->backbone->stage_outputs(torch::zeros({1, 3, h, w}));
  }
  const auto n = static_cast<int64_t>(files.size());
  {
    sp::ProgressBar bar("teacher features", files.size(), o.progress);
    for (int64_t i = 0; i < n; ++i) {
      const cv::Mat bgr = cv::imread(files[static_cast<size_t>(i)].string(), cv::IMREAD_COLOR);
      if (bgr.empty()) throw sp::InputError(files[static_cast<size_t>(i)].string(), 0, "cannot read image");
      const auto t = teacher.features(bgr);
      for (auto& level : levels) {
        const auto& s = shapes[static_cast<size_t>(level.stage)];
        // Area pooling onto the student's grid; normalised below, once every image is in.
        const auto pooled = F::adaptive_avg_pool2d(t[static_cast<size_t>(level.teacher_slot)],
                                                   F::AdaptiveAvgPool2dFuncOptions({s.size(2), s.size(3)}));
        if (!level.targets.defined())
          level.targets = torch::empty({n, pooled.size(1), s.size(2), s.size(3)}, torch::kFloat32);
        level.targets[i].copy_(pooled[0]);
      }
      if (i % 32 == 0) bar.update(static_cast<size_t>(i + 1));
    }
    bar.finish();
  }
  std::vector<torch::Tensor> params = model->parameters();
  for (auto& level : levels) {
    auto& t = level.targets;
    // The teacher's activations (SiLU) are nearly all positive, so any two of its feature vectors
    // are close in angle and matching their mean direction alone already gives a small loss.
    // Subtracting the per-channel mean over the training set makes the cosine measure what differs
    // between places.
    if (o.center_targets) t -= t.mean({0, 2, 3}, /*keepdim=*/true);
    t = F::normalize(t, F::NormalizeFuncOptions().dim(1)).to(torch::kHalf);
    level.proj = torch::nn::Conv2d(
        torch::nn::Conv2dOptions(shapes[static_cast<size_t>(level.stage)].size(1), t.size(1), 1));
    for (const auto& p : level.proj->parameters()) params.push_back(p);
  }
  torch::optim::Adam opt(params, torch::optim::AdamOptions(o.lr));
  LrSchedule sched;
  sched.kind = LrScheduleKind::Cosine;
  sched.warmup_epochs = 0.05;  // of the one "epoch" that is the whole run
  AugmentOptions aug = o.augment;
  aug.crop_max = 0;  // a crop would shift the student's grid against the teacher's targets
  ProcessGroup single(DistOptions{});
  const ValData val = load_val(o.val, o.rules, h, w, true, o.progress);

  DistillStats stats;
  std::vector<double> losses;
  std::uniform_int_distribution<int64_t> pick(0, n - 1);
  sp::ProgressBar bar("distilling", static_cast<size_t>(o.steps), o.progress);
  for (int s = 0; s < o.steps; ++s) {
    const double lr = learning_rate(sched, o.lr, s, o.steps, 1);
    set_lr(opt, lr);
    std::vector<int64_t> idx(static_cast<size_t>(o.batch));
    for (auto& i : idx) i = pick(rng);
    const auto sel = torch::tensor(idx);
    auto images = store.index_select(0, sel).clone();
    std::vector<AugmentKey> keys;
    for (int r = 0; r < o.batch; ++r) keys.push_back({o.seed, 1, static_cast<int64_t>(s) * o.batch + r, 0});
    augment_batch(images, aug, keys);
    model->train();
    const auto outs = model->backbone->stage_outputs(normalise(images));
    auto loss = torch::zeros({});
    for (auto& level : levels)
      loss = loss + level.weight * cosine_loss(level.proj(student_map(model, outs, level.stage)),
                                               level.targets.index_select(0, sel).to(torch::kFloat32));
    opt.zero_grad();
    loss.backward();
    opt.step();
    const double l = loss.item<double>();
    if (!std::isfinite(l))
      throw sp::Error(fmt::format("vpr distill: the loss diverged at step {} (lower --lr)", s + 1));
    losses.push_back(l);
    bar.update(static_cast<size_t>(s + 1), fmt::format("loss {:.4f}", l));
    if ((s + 1) % 100 == 0) {
      spdlog::info("step {}: loss {:.4f} (mean of the last 100), lr {:.3g}", s + 1,
                   mean(losses, losses.size() - 100, 100), lr);
    }
    if (o.eval_every > 0 && (s + 1) % o.eval_every == 0 && (s + 1) < o.steps && !val.sets.empty()) {
      init_centroids(model, store, o.kmeans_images, rng);
      const auto r = evaluate_val(model, val, single);
      spdlog::info("step {}: val R@1 {:.3f} R@5 {:.3f} R@10 {:.3f} ({} queries)", s + 1, r.recall[0],
                   r.recall[1], r.recall[2], r.queries);
    }
  }
  bar.finish();
  init_centroids(model, store, o.kmeans_images, rng);
  save_model(model, o.out);
  const size_t window = std::max<size_t>(1, std::min<size_t>(50, losses.size() / 5));
  stats.steps = o.steps;
  stats.first_loss = mean(losses, 0, window);
  stats.last_loss = mean(losses, losses.size() - window, window);
  if (!val.sets.empty()) {
    stats.val = evaluate_val(model, val, single);
    spdlog::info("val R@1 {:.3f} R@5 {:.3f} R@10 {:.3f} ({} queries)", stats.val->recall[0],
                 stats.val->recall[1], stats.val->recall[2], stats.val->queries);
  }
  stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  spdlog::info("wrote {}: loss {:.4f} → {:.4f} over {} steps, {:.0f} s", o.out.string(), stats.first_loss,
               stats.last_loss, stats.steps, stats.seconds);
  return stats;
}

}  // namespace sp::place
