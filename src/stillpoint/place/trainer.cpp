#include "stillpoint/place/trainer.hpp"

#include <ATen/Parallel.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <fstream>
#include <numeric>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>

#include "stillpoint/common/error.hpp"
#include "stillpoint/common/progress_bar.hpp"
#include "stillpoint/common/timing.hpp"
#include "stillpoint/place/model.hpp"

namespace sp::place {

namespace fs = std::filesystem;

std::vector<PlaceImage> collect_places(const std::vector<fs::path>& dirs) {
  std::vector<PlaceImage> all;
  for (const auto& d : dirs) {
    const auto folders = find_places_folders(d);
    if (folders.empty()) throw sp::InputError(d.string(), 0, "no dynsynth places folder (poses.txt) found");
    for (const auto& f : folders) {
      auto imgs = load_places_folder(f);
      all.insert(all.end(), imgs.begin(), imgs.end());
    }
  }
  return all;
}

namespace {

// Normalised float batch from a uint8 (N,3,H,W) store.
torch::Tensor normalise(const torch::Tensor& u8) {
  static const float kMean[3] = {0.485f, 0.456f, 0.406f};
  static const float kStd[3] = {0.229f, 0.224f, 0.225f};
  const auto mean = torch::from_blob(const_cast<float*>(kMean), {1, 3, 1, 1}).clone();
  const auto std = torch::from_blob(const_cast<float*>(kStd), {1, 3, 1, 1}).clone();
  return (u8.to(torch::kFloat32).div(255.0) - mean) / std;
}

// Every image resized to the model input, RGB, uint8 (N,3,H,W): a few hundred MB at most.
torch::Tensor load_images(const std::vector<PlaceImage>& imgs, int h, int w, bool progress) {
  auto store = torch::empty({static_cast<int64_t>(imgs.size()), 3, h, w}, torch::kUInt8);
  sp::ProgressBar bar("loading images", imgs.size(), progress);
  for (size_t i = 0; i < imgs.size(); ++i) {
    const cv::Mat bgr = cv::imread(imgs[i].file.string(), cv::IMREAD_COLOR);
    if (bgr.empty()) throw sp::InputError(imgs[i].file.string(), 0, "cannot read image");
    // Same resize and colour order as image_to_tensor(); normalisation happens per batch.
    cv::Mat small;
    cv::resize(bgr, small, cv::Size(w, h), 0, 0, cv::INTER_AREA);
    cv::cvtColor(small, small, cv::COLOR_BGR2RGB);
    store[static_cast<int64_t>(i)].copy_(
        torch::from_blob(small.data, {h, w, 3}, torch::kUInt8).permute({2, 0, 1}));
    if (i % 64 == 0) bar.update(i + 1);
  }
  bar.finish();
  return store;
}

torch::Tensor describe_all(ParCNetVLAD& model, const torch::Tensor& store, int batch) {
  torch::NoGradGuard guard;
  model->eval();
  std::vector<torch::Tensor> out;
  for (int64_t i = 0; i < store.size(0); i += batch) {
    const int64_t n = std::min<int64_t>(batch, store.size(0) - i);
    out.push_back(model->forward(normalise(store.narrow(0, i, n))));
  }
  return torch::cat(out, 0);
}

// k-means on L2-normalised local features of a few images: NetVLAD's centroid initialisation.
void init_centroids(ParCNetVLAD& model, const torch::Tensor& store, int images, std::mt19937_64& rng) {
  torch::NoGradGuard guard;
  model->eval();
  std::vector<int64_t> idx(static_cast<size_t>(store.size(0)));
  std::iota(idx.begin(), idx.end(), 0);
  std::shuffle(idx.begin(), idx.end(), rng);
  idx.resize(std::min<size_t>(idx.size(), static_cast<size_t>(images)));
  std::vector<torch::Tensor> feats;
  for (size_t i = 0; i < idx.size(); i += 16) {
    const auto sel =
        torch::tensor(std::vector<int64_t>(idx.begin() + i, idx.begin() + std::min(idx.size(), i + 16)));
    auto f = model->features(normalise(store.index_select(0, sel)));
    f = torch::nn::functional::normalize(f, torch::nn::functional::NormalizeFuncOptions().dim(1));
    feats.push_back(f.permute({0, 2, 3, 1}).reshape({-1, f.size(1)}));
  }
  const auto x = torch::cat(feats, 0);
  const int64_t k = model->cfg.clusters;
  if (x.size(0) < k) throw sp::Error("too few features for k-means: use more --kmeans-images");
  auto centres = x.index_select(0, torch::randperm(x.size(0)).narrow(0, 0, k)).clone();
  for (int it = 0; it < 25; ++it) {
    const auto assign = torch::cdist(x, centres).argmin(1);
    for (int64_t c = 0; c < k; ++c) {
      const auto members = x.index({assign == c});
      if (members.size(0) > 0) centres[c] = members.mean(0);
    }
  }
  centres = torch::nn::functional::normalize(centres, torch::nn::functional::NormalizeFuncOptions().dim(1));
  // Sharpness as in NetVLAD: make the best cluster ~100× likelier than the second on average.
  const auto dots = std::get<0>(torch::matmul(x, centres.t()).topk(2, 1));
  const double gap = (dots.select(1, 0) - dots.select(1, 1)).mean().item<double>();
  const double alpha = -std::log(0.01) / std::max(gap, 1e-3);
  model->vlad->init_from_centroids(centres, alpha);
  spdlog::info("NetVLAD centroids from {} features of {} images, alpha {:.1f}", x.size(0), idx.size(), alpha);
}

struct Mining {
  std::vector<std::vector<int>> positives;  // per image
  std::vector<int> queries;                 // images with a positive
};

Mining build_mining(const std::vector<PlaceImage>& imgs, const PlaceRules& rules) {
  Mining m;
  m.positives.resize(imgs.size());
  for (size_t i = 0; i < imgs.size(); ++i) {
    for (size_t j = 0; j < imgs.size(); ++j) {
      if (i != j && is_positive(imgs[i], imgs[j], rules)) m.positives[i].push_back(static_cast<int>(j));
    }
    if (!m.positives[i].empty()) m.queries.push_back(static_cast<int>(i));
  }
  return m;
}

}  // namespace

std::vector<EpochStats> train_model(const TrainOptions& o) {
  if (o.threads > 0) at::set_num_threads(o.threads);
  torch::manual_seed(o.seed);
  std::mt19937_64 rng(o.seed);
  const auto imgs = collect_places(o.data);
  const auto mining = build_mining(imgs, o.rules);
  if (mining.queries.empty()) throw sp::Error("no training image has a positive: render more views per room");
  spdlog::info("training: {} images, {} with positives", imgs.size(), mining.queries.size());

  ParCNetVLAD model{nullptr};
  int start_epoch = 0;
  const fs::path ckpt = o.out.string() + ".ckpt";
  if (!o.resume.empty()) {
    model = load_model(o.resume);
    std::ifstream st(o.resume.string() + ".epoch");
    if (!(st >> start_epoch)) throw sp::InputError(o.resume.string() + ".epoch", 1, "missing epoch count");
    spdlog::info("resuming {} after epoch {}", o.resume.string(), start_epoch);
  } else {
    model = ParCNetVLAD(o.model);
  }
  spdlog::info("model: {}", model->cfg.summary());
  const auto store = load_images(imgs, model->cfg.input_height, model->cfg.input_width, o.progress);
  if (o.resume.empty()) init_centroids(model, store, o.kmeans_images, rng);

  std::unique_ptr<torch::optim::Optimizer> opt;
  if (o.optimizer == "sgd") {
    opt = std::make_unique<torch::optim::SGD>(model->parameters(),
                                              torch::optim::SGDOptions(o.lr).momentum(0.9));
  } else if (o.optimizer == "adam") {
    opt = std::make_unique<torch::optim::Adam>(model->parameters(), torch::optim::AdamOptions(o.lr));
  } else {
    throw sp::Error("optimizer must be adam or sgd, not " + o.optimizer);
  }
  if (!o.resume.empty() && fs::exists(o.resume.string() + ".optim"))
    torch::load(*opt, o.resume.string() + ".optim");

  std::vector<EpochStats> stats;
  for (int epoch = start_epoch + 1; epoch <= o.epochs; ++epoch) {
    // Per-epoch seeds keep a resumed run identical to an uninterrupted one.
    torch::manual_seed(o.seed * 1000 + static_cast<std::uint64_t>(epoch));
    std::mt19937_64 erng(o.seed * 1000 + static_cast<std::uint64_t>(epoch));
    sp::Stopwatch sw;
    std::vector<int> order = mining.queries;
    std::shuffle(order.begin(), order.end(), erng);
    order.resize(std::min<size_t>(order.size(), static_cast<size_t>(o.queries_per_epoch)));
    EpochStats es;
    es.epoch = epoch;
    double loss_sum = 0, active = 0;
    int steps = 0, pairs = 0;
    torch::Tensor cache;
    std::uniform_int_distribution<int> pick(0, static_cast<int>(imgs.size()) - 1);
    sp::ProgressBar bar(fmt::format("epoch {}/{}", epoch, o.epochs), order.size(), o.progress);
    for (size_t b = 0; b < order.size(); b += static_cast<size_t>(o.batch)) {
      if (b % static_cast<size_t>(std::max(o.refresh_every, 1)) < static_cast<size_t>(o.batch) ||
          !cache.defined()) {
        cache = describe_all(model, store, 32);
      }
      std::vector<int64_t> q_idx, p_idx, n_idx;
      const size_t end = std::min(order.size(), b + static_cast<size_t>(o.batch));
      for (size_t i = b; i < end; ++i) {
        const int q = order[i];
        const auto qd = cache[q];
        // Best positive: the closest in descriptor space (the view most likely to overlap).
        const auto& pos = mining.positives[static_cast<size_t>(q)];
        const auto pd =
            (cache.index_select(0, torch::tensor(std::vector<int64_t>(pos.begin(), pos.end()))) - qd)
                .pow(2)
                .sum(1);
        const int best_pos = pos[static_cast<size_t>(pd.argmin().item<int64_t>())];
        // Hard negatives: the closest of a random pool of true negatives.
        std::vector<int64_t> pool;
        for (int tries = 0; static_cast<int>(pool.size()) < o.negative_pool && tries < 20 * o.negative_pool;
             ++tries) {
          const int c = pick(erng);
          if (is_negative(imgs[static_cast<size_t>(q)], imgs[static_cast<size_t>(c)], o.rules))
            pool.push_back(c);
        }
        if (static_cast<int>(pool.size()) < o.negatives) continue;
        const auto pool_t = torch::tensor(pool);
        const auto nd = (cache.index_select(0, pool_t) - qd).pow(2).sum(1);
        const auto hard = std::get<1>(nd.topk(o.negatives, 0, /*largest=*/false));
        q_idx.push_back(q);
        p_idx.push_back(best_pos);
        for (int64_t k = 0; k < o.negatives; ++k)
          n_idx.push_back(pool[static_cast<size_t>(hard[k].item<int64_t>())]);
      }
      if (q_idx.empty()) continue;
      model->train();
      const auto all = torch::cat({torch::tensor(q_idx), torch::tensor(p_idx), torch::tensor(n_idx)});
      const auto d = model->forward(normalise(store.index_select(0, all)));
      const int64_t B = static_cast<int64_t>(q_idx.size());
      const auto qd = d.narrow(0, 0, B), pd = d.narrow(0, B, B);
      const auto nd = d.narrow(0, 2 * B, B * o.negatives).view({B, o.negatives, -1});
      const auto loss = triplet_loss(qd, pd, nd, o.margin);
      opt->zero_grad();
      loss.backward();
      opt->step();
      {
        torch::NoGradGuard g;
        const auto viol = (qd - pd).pow(2).sum(1, true) + o.margin - (qd.unsqueeze(1) - nd).pow(2).sum(2);
        active += (viol > 0).sum().item<double>();
        pairs += static_cast<int>(viol.numel());
      }
      loss_sum += loss.item<double>();
      ++steps;
      bar.update(end, fmt::format("loss {:.4f}", loss_sum / steps));
    }
    bar.finish();
    es.loss = steps > 0 ? loss_sum / steps : 0.0;
    es.active = pairs > 0 ? active / pairs : 0.0;
    es.seconds = sw.elapsed_ms() / 1000.0;
    stats.push_back(es);
    spdlog::info("epoch {}: loss {:.4f}, active negatives {:.1f} %, {:.0f} s", epoch, es.loss,
                 100 * es.active, es.seconds);
    save_model(model, ckpt);
    torch::save(*opt, ckpt.string() + ".optim");
    std::ofstream(ckpt.string() + ".epoch") << epoch << "\n";
  }
  save_model(model, o.out);
  spdlog::info("wrote {}", o.out.string());
  return stats;
}

}  // namespace sp::place
