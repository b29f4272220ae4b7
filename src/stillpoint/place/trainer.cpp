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
#include "stillpoint/place/distributed.hpp"
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

// Descriptors of every image, in chunks of `batch` rows; the ranks share the chunks round-robin and
// sum their zero-padded parts, so every rank ends with the same cache a single process would compute.
torch::Tensor describe_all(ParCNetVLAD& model, const torch::Tensor& store, int batch, ProcessGroup& pg) {
  torch::NoGradGuard guard;
  model->eval();
  torch::Tensor out;
  for (int64_t i = 0, chunk = 0; i < store.size(0); i += batch, ++chunk) {
    if (chunk % pg.size() != pg.rank()) continue;
    const int64_t n = std::min<int64_t>(batch, store.size(0) - i);
    const auto d = model->forward(normalise(store.narrow(0, i, n)));
    if (!out.defined()) out = torch::zeros({store.size(0), d.size(1)});
    out.narrow(0, i, n).copy_(d);
  }
  if (!out.defined()) out = torch::zeros({store.size(0), model->cfg.descriptor_dim()});
  pg.all_reduce(out, ProcessGroup::Op::Sum, "the descriptor-cache refresh");
  return out;
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

// Replaces every parameter and buffer by rank 0's (one flat broadcast). Returns the largest change that
// made here: 0 on rank 0, and on the others as long as they step in lockstep.
double broadcast_weights(ParCNetVLAD& model, ProcessGroup& pg, const char* what) {
  if (pg.size() == 1) return 0.0;
  torch::NoGradGuard g;
  std::vector<torch::Tensor> ts = model->parameters();
  for (const auto& b : model->buffers()) ts.push_back(b);
  std::vector<torch::Tensor> flat;
  for (const auto& t : ts) flat.push_back(t.reshape({-1}));
  auto all = torch::cat(flat);
  pg.broadcast(all, 0, what);
  double change = 0;
  int64_t at = 0;
  for (auto& t : ts) {
    const auto mine = all.narrow(0, at, t.numel()).view(t.sizes());
    change = std::max(change, (mine - t).abs().max().item<double>());
    t.copy_(mine);
    at += t.numel();
  }
  return change;
}

// Ranks that disagree on data or options would silently train different things (or deadlock on a
// different step count): compare min and max of each value over the ranks and name the first mismatch.
void check_same_on_all_ranks(ProcessGroup& pg, const std::vector<std::pair<const char*, double>>& values) {
  if (pg.size() == 1) return;
  auto t = torch::empty({2 * static_cast<int64_t>(values.size())}, torch::kFloat64);
  for (size_t i = 0; i < values.size(); ++i) {
    t[static_cast<int64_t>(2 * i)] = values[i].second;
    t[static_cast<int64_t>(2 * i + 1)] = -values[i].second;
  }
  pg.all_reduce(t, ProcessGroup::Op::Max, "the start-up consistency check");
  for (size_t i = 0; i < values.size(); ++i) {
    const double hi = t[static_cast<int64_t>(2 * i)].item<double>();
    const double lo = -t[static_cast<int64_t>(2 * i + 1)].item<double>();
    if (hi != lo) {
      throw sp::Error(
          fmt::format("distributed training: the ranks disagree on {} (from {} to {}): every rank "
                      "needs the same --data, training options and --resume checkpoint",
                      values[i].first, lo, hi));
    }
  }
}

}  // namespace

std::vector<EpochStats> train_model(const TrainOptions& o) {
  if (o.threads > 0) at::set_num_threads(o.threads);
  // Rendezvous (options validated there) before the slow image loading, so a misconfigured rank fails
  // at once.
  ProcessGroup pg(o.dist);
  const bool lead = pg.rank() == 0;
  const bool progress = o.progress && lead;
  torch::manual_seed(o.seed);
  std::mt19937_64 rng(o.seed);
  const auto imgs = collect_places(o.data);
  const auto mining = build_mining(imgs, o.rules);
  if (mining.queries.empty()) throw sp::Error("no training image has a positive: render more views per room");
  if (lead) spdlog::info("training: {} images, {} with positives", imgs.size(), mining.queries.size());

  ParCNetVLAD model{nullptr};
  int start_epoch = 0;
  const fs::path ckpt = o.out.string() + ".ckpt";
  if (!o.resume.empty()) {
    model = load_model(o.resume);
    std::ifstream st(o.resume.string() + ".epoch");
    if (!(st >> start_epoch)) throw sp::InputError(o.resume.string() + ".epoch", 1, "missing epoch count");
    if (lead) spdlog::info("resuming {} after epoch {}", o.resume.string(), start_epoch);
  } else {
    model = ParCNetVLAD(o.model);
  }
  if (lead) spdlog::info("model: {}", model->cfg.summary());
  const auto store = load_images(imgs, model->cfg.input_height, model->cfg.input_width, progress);
  if (o.resume.empty() && lead) init_centroids(model, store, o.kmeans_images, rng);
  // Every rank starts from rank 0's weights (random init and k-means centroids alike).
  broadcast_weights(model, pg, "the initial weight broadcast");

  std::unique_ptr<torch::optim::Optimizer> opt;
  if (o.optimizer == "sgd") {
    opt = std::make_unique<torch::optim::SGD>(model->parameters(),
                                              torch::optim::SGDOptions(o.lr).momentum(0.9));
  } else if (o.optimizer == "adam") {
    opt = std::make_unique<torch::optim::Adam>(model->parameters(), torch::optim::AdamOptions(o.lr));
  } else {
    throw sp::Error("optimizer must be adam or sgd, not " + o.optimizer);
  }
  bool optim_loaded = false;
  if (!o.resume.empty() && fs::exists(o.resume.string() + ".optim")) {
    torch::load(*opt, o.resume.string() + ".optim");
    optim_loaded = true;
  }
  const auto params = model->parameters();
  int64_t n_params = 0;
  for (const auto& p : params) n_params += p.numel();
  check_same_on_all_ranks(pg, {{"the image count", static_cast<double>(imgs.size())},
                               {"the query count", static_cast<double>(mining.queries.size())},
                               {"the parameter count", static_cast<double>(n_params)},
                               {"the resumed epoch", start_epoch},
                               {"whether an optimiser state was resumed", optim_loaded ? 1.0 : 0.0},
                               {"--epochs", o.epochs},
                               {"--batch", o.batch},
                               {"--queries-per-epoch", o.queries_per_epoch},
                               {"--negatives", o.negatives},
                               {"--refresh-every", o.refresh_every},
                               {"--seed", static_cast<double>(o.seed)}});

  // One step consumes `batch` queries on each rank: rank r takes [b + r·batch, b + (r+1)·batch).
  const size_t step_queries = static_cast<size_t>(o.batch) * static_cast<size_t>(pg.size());
  std::vector<EpochStats> stats;
  for (int epoch = start_epoch + 1; epoch <= o.epochs; ++epoch) {
    // Per-epoch seeds keep a resumed run identical to an uninterrupted one. The query order is the
    // same on every rank; the torch RNG (stochastic depth) differs per rank so masks are independent.
    torch::manual_seed(o.seed * 1000 + static_cast<std::uint64_t>(epoch) +
                       1000003ULL * static_cast<std::uint64_t>(pg.rank()));
    std::mt19937_64 erng(o.seed * 1000 + static_cast<std::uint64_t>(epoch));
    sp::Stopwatch sw;
    std::vector<int> order = mining.queries;
    std::shuffle(order.begin(), order.end(), erng);
    order.resize(std::min<size_t>(order.size(), static_cast<size_t>(o.queries_per_epoch)));
    EpochStats es;
    es.epoch = epoch;
    double loss_sum = 0, active = 0, pairs = 0;
    int steps = 0;
    torch::Tensor cache;
    std::uniform_int_distribution<int> pick(0, static_cast<int>(imgs.size()) - 1);
    sp::ProgressBar bar(fmt::format("epoch {}/{}", epoch, o.epochs), order.size(), progress);
    for (size_t b = 0; b < order.size(); b += step_queries) {
      if (b % static_cast<size_t>(std::max(o.refresh_every, 1)) < step_queries || !cache.defined()) {
        cache = describe_all(model, store, 32, pg);
      }
      std::vector<int64_t> q_idx, p_idx, n_idx;
      const size_t begin =
          std::min(order.size(), b + static_cast<size_t>(pg.rank()) * static_cast<size_t>(o.batch));
      const size_t end = std::min(order.size(), begin + static_cast<size_t>(o.batch));
      for (size_t i = begin; i < end; ++i) {
        const int q = order[i];
        const auto qd = cache[q];
        // Best positive: the closest in descriptor space (the view most likely to overlap).
        const auto& pos = mining.positives[static_cast<size_t>(q)];
        const auto pd =
            (cache.index_select(0, torch::tensor(std::vector<int64_t>(pos.begin(), pos.end()))) - qd)
                .pow(2)
                .sum(1);
        const int best_pos = pos[static_cast<size_t>(pd.argmin().item<int64_t>())];
        // Hard negatives: the closest of a random pool of true negatives. The pool's RNG depends on
        // the query's place in the epoch only, so how the step is split over ranks changes nothing.
        std::seed_seq qseed{static_cast<std::uint32_t>(o.seed), static_cast<std::uint32_t>(o.seed >> 32),
                            static_cast<std::uint32_t>(epoch), static_cast<std::uint32_t>(i)};
        std::mt19937_64 qrng(qseed);
        std::vector<int64_t> pool;
        for (int tries = 0; static_cast<int>(pool.size()) < o.negative_pool && tries < 20 * o.negative_pool;
             ++tries) {
          const int c = pick(qrng);
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
      model->train();
      opt->zero_grad();
      const int64_t B = static_cast<int64_t>(q_idx.size());
      double local[4] = {static_cast<double>(B), 0, 0, 0};  // triplets, loss sum, active pairs, pairs
      if (B > 0) {
        const auto all = torch::cat({torch::tensor(q_idx), torch::tensor(p_idx), torch::tensor(n_idx)});
        const auto d = model->forward(normalise(store.index_select(0, all)));
        const auto qd = d.narrow(0, 0, B), pd = d.narrow(0, B, B);
        const auto nd = d.narrow(0, 2 * B, B * o.negatives).view({B, o.negatives, -1});
        // Summed here and divided by the step's total triplet count after the all-reduce: the
        // gradient is exactly that of the mean loss over the whole step's batch, however it is split.
        const auto loss_sum_local = triplet_loss(qd, pd, nd, o.margin) * static_cast<double>(B);
        loss_sum_local.backward();
        torch::NoGradGuard g;
        const auto viol = (qd - pd).pow(2).sum(1, true) + o.margin - (qd.unsqueeze(1) - nd).pow(2).sum(2);
        local[1] = loss_sum_local.item<double>();
        local[2] = (viol > 0).sum().item<double>();
        local[3] = static_cast<double>(viol.numel());
      }
      double global[4];
      {
        torch::NoGradGuard g;
        if (pg.size() == 1) {
          std::copy(local, local + 4, global);
        } else {
          // One all-reduce per step: every gradient (zeros where this rank had no triplets) plus the
          // four counters, summed over the ranks.
          std::vector<torch::Tensor> flat;
          for (const auto& p : params)
            flat.push_back(p.grad().defined() ? p.grad().reshape({-1}) : torch::zeros({p.numel()}));
          flat.push_back(torch::tensor(std::vector<float>(local, local + 4)));  // counts stay exact
          auto buf = torch::cat(flat);
          pg.all_reduce(buf, ProcessGroup::Op::Sum, "the gradient all-reduce");
          const auto counters = buf.narrow(0, buf.size(0) - 4, 4);
          for (int k = 0; k < 4; ++k) global[k] = counters[k].item<double>();
          int64_t at = 0;
          for (const auto& p : params) {
            if (!p.grad().defined()) p.mutable_grad() = torch::zeros_like(p);
            p.mutable_grad().copy_(buf.narrow(0, at, p.numel()).view(p.sizes()));
            at += p.numel();
          }
        }
        if (global[0] == 0) continue;  // no rank found a usable query: no step anywhere
        for (const auto& p : params)
          if (p.grad().defined()) p.mutable_grad().div_(global[0]);
      }
      opt->step();
      active += global[2];
      pairs += global[3];
      loss_sum += global[1] / global[0];
      ++steps;
      bar.update(std::min(order.size(), b + step_queries), fmt::format("loss {:.4f}", loss_sum / steps));
    }
    bar.finish();
    // Identical gradients keep the ranks identical only while every rank rounds alike; machines with
    // different CPUs (vector widths) may not. Re-sync to rank 0 each epoch and say if anything moved.
    es.rank_drift = broadcast_weights(model, pg, "the end-of-epoch weight sync");
    if (es.rank_drift > 0)
      spdlog::warn("rank {}: weights had drifted from rank 0's by up to {:.3g}; re-synchronised", pg.rank(),
                   es.rank_drift);
    es.loss = steps > 0 ? loss_sum / steps : 0.0;
    es.active = pairs > 0 ? active / pairs : 0.0;
    es.seconds = sw.elapsed_ms() / 1000.0;
    stats.push_back(es);
    if (!lead) continue;  // the other ranks hold identical weights: one writer is enough
    spdlog::info("epoch {}: loss {:.4f}, active negatives {:.1f} %, {:.0f} s", epoch, es.loss,
                 100 * es.active, es.seconds);
    save_model(model, ckpt);
    torch::save(*opt, ckpt.string() + ".optim");
    std::ofstream(ckpt.string() + ".epoch") << epoch << "\n";
  }
  if (lead) {
    save_model(model, o.out);
    spdlog::info("wrote {}", o.out.string());
  }
  return stats;
}

}  // namespace sp::place
