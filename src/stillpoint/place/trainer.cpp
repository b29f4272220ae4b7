#include "stillpoint/place/trainer.hpp"

#include <ATen/Parallel.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <numeric>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <set>

#include "stillpoint/common/error.hpp"
#include "stillpoint/common/progress_bar.hpp"
#include "stillpoint/common/timing.hpp"
#include "stillpoint/place/distributed.hpp"
#include "stillpoint/place/model.hpp"
#include "stillpoint/place/train_data.hpp"
#include "stillpoint/place/training_log.hpp"

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

void validate(const TrainOptions& o) {
  const auto need = [](bool ok, const std::string& what) {
    if (!ok) throw sp::Error("vpr train: " + what);
  };
  need(!o.data.empty(), "no --data folder");
  need(!o.out.empty(), "no --out file");
  need(o.epochs >= 1 && o.epochs <= 1000, fmt::format("epochs must be in [1, 1000], not {}", o.epochs));
  need(std::isfinite(o.lr) && o.lr >= 0 && o.lr <= 1, fmt::format("lr must be in [0, 1], not {}", o.lr));
  need(o.optimizer == "adam" || o.optimizer == "sgd", "optimizer must be adam or sgd, not " + o.optimizer);
  need(o.margin >= 0, fmt::format("margin must be >= 0, not {}", o.margin));
  need(o.negatives >= 1, fmt::format("negatives must be >= 1, not {}", o.negatives));
  need(o.negative_pool >= o.negatives,
       fmt::format("the negative pool ({}) must hold at least --negatives ({})", o.negative_pool,
                   o.negatives));
  need(o.queries_per_epoch >= 1, "queries per epoch must be >= 1");
  need(o.batch >= 1, fmt::format("batch must be >= 1, not {}", o.batch));
  need(o.refresh_every >= 1, "refresh-every must be >= 1");
  need(o.kmeans_images >= 1, "kmeans-images must be >= 1");
  need(o.init.empty() || o.resume.empty(), "--init and --resume exclude each other");
  need(o.patience >= 0, fmt::format("patience must be >= 0, not {}", o.patience));
  need(o.patience == 0 || !o.val.empty(), "--patience needs --val (early stopping watches the val recall)");
  validate(o.lr_schedule);
  validate(o.augment);
}

using namespace detail;

namespace {

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

// A val room that is also trained on would make the recall (and early stopping) meaningless. Compares
// places folders and room names (scene.txt): a re-rendered copy of a training room is the same room.
// Runs before any image is loaded, so the mistake costs nothing.
void check_val_disjoint(const TrainOptions& o, const std::vector<PlaceImage>& train_imgs) {
  std::set<fs::path> train_dirs;
  std::set<std::string> train_rooms;
  for (const auto& d : o.data)
    for (const auto& f : find_places_folders(d)) train_dirs.insert(fs::weakly_canonical(f));
  for (const auto& im : train_imgs) train_rooms.insert(im.room);
  for (const auto& dir : o.val) {
    if (!fs::is_directory(dir)) throw sp::InputError(dir.string(), 0, "--val folder not found");
    for (const auto& folder : find_places_folders(dir)) {
      if (train_dirs.count(fs::weakly_canonical(folder)))
        throw sp::InputError(folder.string(), 0,
                             "--val folder is also in --data: val rooms must never be trained on");
      const auto imgs = load_places_folder(folder);
      if (train_rooms.count(imgs.front().room))
        throw sp::InputError(
            folder.string(), 0,
            "--val room '" + imgs.front().room + "' is also a training room (same scene.txt)");
    }
  }
}

// <ckpt>.epoch: the last finished epoch, then (with --val) "best_epoch best_R@1" so that a resumed run
// keeps comparing against the best so far and still writes that epoch's weights (<ckpt>.best).
struct CheckpointState {
  int epoch = 0;
  int best_epoch = 0;
  double best_r1 = -1;
};

CheckpointState read_checkpoint_state(const fs::path& ckpt) {
  const fs::path file = ckpt.string() + ".epoch";
  std::ifstream st(file);
  CheckpointState c;
  if (!(st >> c.epoch)) throw sp::InputError(file.string(), 1, "missing epoch count");
  if (!(st >> c.best_epoch >> c.best_r1)) c.best_epoch = 0, c.best_r1 = -1;  // before validation existed
  return c;
}

// Checkpoint files are written to <file>.tmp first and renamed into place once all of them are
// written, <ckpt>.epoch last: a kill while writing leaves the previous complete set (plus stray .tmp
// files, overwritten next time), and .epoch never names an epoch whose weights are not in place.
fs::path tmp_path(const fs::path& file) { return file.string() + ".tmp"; }

void write_checkpoint_state(const fs::path& file, const CheckpointState& c) {
  std::ofstream st(file);
  st << c.epoch << "\n";
  if (c.best_epoch > 0) st << c.best_epoch << " " << std::setprecision(17) << c.best_r1 << "\n";
  st.close();
  if (!st) throw sp::Error("cannot write the checkpoint state " + file.string());
}

// The log of the run being resumed: named after its --out, i.e. the checkpoint path without the
// ".ckpt" that train_model appends. A checkpoint named otherwise: this run's --out (no other guess).
fs::path resumed_log_base(const fs::path& resume, const fs::path& out) {
  const std::string r = resume.string();
  const std::string suffix = ".ckpt";
  if (r.size() > suffix.size() && r.compare(r.size() - suffix.size(), suffix.size(), suffix) == 0)
    return r.substr(0, r.size() - suffix.size());
  return out;
}

}  // namespace

std::vector<EpochStats> train_model(const TrainOptions& o) {
  validate(o);
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
  check_val_disjoint(o, imgs);

  ParCNetVLAD model{nullptr};
  CheckpointState resumed;
  const fs::path ckpt = o.out.string() + ".ckpt";
  if (!o.resume.empty()) {
    model = load_model(o.resume);
    resumed = read_checkpoint_state(o.resume);
    if (lead) spdlog::info("resuming {} after epoch {}", o.resume.string(), resumed.epoch);
  } else if (!o.init.empty()) {
    if (!fs::exists(o.init)) throw sp::InputError(o.init.string(), 0, "--init model not found");
    model = load_model(o.init);
    if (lead) spdlog::info("starting from {} (its NetVLAD centroids kept)", o.init.string());
  } else {
    model = ParCNetVLAD(o.model);
  }
  const int start_epoch = resumed.epoch;
  if (lead) spdlog::info("model: {}", model->cfg.summary());
  std::vector<fs::path> files;
  for (const auto& im : imgs) files.push_back(im.file);
  const auto store =
      load_images(files, model->cfg.input_height, model->cfg.input_width, progress, "loading images");
  const ValData val =
      load_val(o.val, o.rules, model->cfg.input_height, model->cfg.input_width, lead, o.progress && lead);
  // Best-epoch bookkeeping (only with --val). The best weights live in <ckpt>.best; a resumed run
  // starts from the checkpoint's record and its .best file.
  EarlyStopping stopper(o.patience);
  const fs::path best_file = ckpt.string() + ".best";
  if (!val.sets.empty() && resumed.best_epoch > 0) {
    stopper.restore(resumed.best_r1, resumed.best_epoch);
    const fs::path resumed_best = o.resume.string() + ".best";
    // Checked on every rank (all of them read o.resume): a throw on rank 0 alone would leave the
    // others waiting in the weight broadcast below until the timeout.
    if (!fs::exists(resumed_best))
      throw sp::InputError(resumed_best.string(), 0,
                           "the best epoch's weights of the resumed run are missing");
    // This run's <ckpt>.epoch will record the resumed best epoch, so its <ckpt>.best must hold those
    // weights even if no later epoch beats them (else a second --resume of this --out would fail).
    // Rank 0 only, like every write: should the copy throw, the other ranks wait in the broadcast
    // below until the timeout (see the end-of-epoch writes).
    if (lead && !(fs::exists(best_file) && fs::equivalent(resumed_best, best_file))) {
      if (ckpt.has_parent_path()) fs::create_directories(ckpt.parent_path());
      fs::copy_file(resumed_best, tmp_path(best_file), fs::copy_options::overwrite_existing);
      fs::rename(tmp_path(best_file), best_file);
    }
  }
  if (o.resume.empty() && o.init.empty() && lead) init_centroids(model, store, o.kmeans_images, rng);
  // Every rank starts from rank 0's weights (random init and k-means centroids alike).
  broadcast_weights(model, pg, "the initial weight broadcast");

  std::unique_ptr<torch::optim::Optimizer> opt;
  if (o.optimizer == "sgd") {
    opt = std::make_unique<torch::optim::SGD>(model->parameters(),
                                              torch::optim::SGDOptions(o.lr).momentum(0.9));
  } else {
    opt = std::make_unique<torch::optim::Adam>(model->parameters(), torch::optim::AdamOptions(o.lr));
  }
  bool optim_loaded = false;
  if (!o.resume.empty() && fs::exists(o.resume.string() + ".optim")) {
    torch::load(*opt, o.resume.string() + ".optim");
    optim_loaded = true;
  }
  const auto params = model->parameters();
  int64_t n_params = 0;
  for (const auto& p : params) n_params += p.numel();
  const auto& aug = o.augment;
  check_same_on_all_ranks(pg, {{"the image count", static_cast<double>(imgs.size())},
                               {"the query count", static_cast<double>(mining.queries.size())},
                               {"the parameter count", static_cast<double>(n_params)},
                               {"the resumed epoch", start_epoch},
                               {"the resumed best val epoch", stopper.best_epoch()},
                               {"the resumed best val R@1", stopper.best()},
                               {"whether an optimiser state was resumed", optim_loaded ? 1.0 : 0.0},
                               {"the val image count", val.store.defined() ? val.store.size(0) : 0.0},
                               {"--epochs", o.epochs},
                               {"--batch", o.batch},
                               {"--queries-per-epoch", o.queries_per_epoch},
                               {"--negatives", o.negatives},
                               {"--refresh-every", o.refresh_every},
                               {"--patience", o.patience},
                               {"--lr", o.lr},
                               {"--margin", o.margin},
                               {"--lr-schedule", static_cast<double>(o.lr_schedule.kind)},
                               {"--warmup-epochs", o.lr_schedule.warmup_epochs},
                               {"--lr-gamma", o.lr_schedule.step_gamma},
                               {"--lr-step-epochs", o.lr_schedule.step_epochs},
                               {"the cosine's final factor", o.lr_schedule.final_factor},
                               {"--augment", aug.enabled ? 1.0 : 0.0},
                               {"the augmentation's brightness range", aug.brightness},
                               {"the augmentation's contrast range", aug.contrast},
                               {"the augmentation's saturation range", aug.saturation},
                               {"the augmentation's gamma range", aug.gamma},
                               {"the augmentation's blur probability", aug.blur_probability},
                               {"the augmentation's largest blur sigma", aug.blur_sigma_max},
                               {"the augmentation's largest noise sigma", aug.noise_sigma_max},
                               {"the augmentation's largest crop", aug.crop_max},
                               {"--seed", static_cast<double>(o.seed)}});

  // One step consumes `batch` queries on each rank: rank r takes [b + r·batch, b + (r+1)·batch).
  const size_t step_queries = static_cast<size_t>(o.batch) * static_cast<size_t>(pg.size());
  const size_t epoch_queries =
      std::min<size_t>(mining.queries.size(), static_cast<size_t>(o.queries_per_epoch));
  const auto steps_per_epoch = static_cast<int64_t>((epoch_queries + step_queries - 1) / step_queries);
  if (lead)
    spdlog::info("lr {} ({}, warm-up {} epochs, {} steps per epoch), augmentation {}, validation {}", o.lr,
                 to_string(o.lr_schedule.kind), o.lr_schedule.warmup_epochs, steps_per_epoch,
                 o.augment.enabled ? "on" : "off",
                 val.sets.empty() ? std::string("off")
                                  : fmt::format("on ({} sets, patience {})", val.sets.size(), o.patience));
  // The log keeps the epochs of the run this one resumes (rows up to the resumed epoch), read from
  // that run's log (<resume> without ".ckpt"), which differs from this run's when --out changed. Read
  // on every rank, so that an unreadable log fails them all before the first collective.
  std::vector<EpochStats> log_rows;
  if (start_epoch > 0) {
    for (const auto& r : read_training_log(resumed_log_base(o.resume, o.out)))
      if (r.epoch <= start_epoch && lead) log_rows.push_back(r);
  }
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
    order.resize(epoch_queries);
    EpochStats es;
    es.epoch = epoch;
    double loss_sum = 0, active = 0, pairs = 0;
    int steps = 0;
    torch::Tensor cache;
    std::uniform_int_distribution<int> pick(0, static_cast<int>(imgs.size()) - 1);
    sp::ProgressBar bar(fmt::format("epoch {}/{}", epoch, o.epochs), order.size(), progress);
    for (size_t b = 0; b < order.size(); b += step_queries) {
      // The schedule is a function of the global step only: resumed and distributed runs agree.
      const int64_t global_step =
          static_cast<int64_t>(epoch - 1) * steps_per_epoch + static_cast<int64_t>(b / step_queries);
      es.lr = learning_rate(o.lr_schedule, o.lr, global_step, steps_per_epoch, o.epochs);
      set_lr(*opt, es.lr);
      if (b % static_cast<size_t>(std::max(o.refresh_every, 1)) < step_queries || !cache.defined()) {
        cache = describe_all(model, store, 32, pg);
      }
      std::vector<int64_t> q_idx, p_idx, n_idx;
      std::vector<int64_t> q_pos;  // each triplet's query position in the epoch: the augmentation key
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
        q_pos.push_back(static_cast<int64_t>(i));
        for (int64_t k = 0; k < o.negatives; ++k)
          n_idx.push_back(pool[static_cast<size_t>(hard[k].item<int64_t>())]);
      }
      model->train();
      opt->zero_grad();
      const int64_t B = static_cast<int64_t>(q_idx.size());
      double local[4] = {static_cast<double>(B), 0, 0, 0};  // triplets, loss sum, active pairs, pairs
      if (B > 0) {
        const auto all = torch::cat({torch::tensor(q_idx), torch::tensor(p_idx), torch::tensor(n_idx)});
        auto images = store.index_select(0, all);
        if (o.augment.enabled) {
          // Rows: B queries, B positives, then B × negatives; keyed by (seed, epoch, position, slot).
          std::vector<AugmentKey> keys;
          for (int64_t j = 0; j < B; ++j) keys.push_back({o.seed, epoch, q_pos[static_cast<size_t>(j)], 0});
          for (int64_t j = 0; j < B; ++j) keys.push_back({o.seed, epoch, q_pos[static_cast<size_t>(j)], 1});
          for (int64_t j = 0; j < B; ++j)
            for (int k = 0; k < o.negatives; ++k)
              keys.push_back({o.seed, epoch, q_pos[static_cast<size_t>(j)], 2 + k});
          augment_batch(images, o.augment, keys);
        }
        const auto d = model->forward(normalise(images));
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
    es.seconds = sw.elapsed_ms() / 1000.0;  // training only: validation is timed on its own below
    bool improved = false;
    if (!val.sets.empty()) {
      sp::Stopwatch vw;
      es.val = evaluate_val(model, val, pg);  // all ranks take part, all get rank 0's figures
      improved = stopper.update(epoch, es.val->recall[0]);
      if (lead)
        spdlog::info("epoch {}: val R@1 {:.3f} R@5 {:.3f} R@10 {:.3f} ({} queries, {:.0f} s){}", epoch,
                     es.val->recall[0], es.val->recall[1], es.val->recall[2], es.val->queries,
                     vw.elapsed_ms() / 1000.0, improved ? ", best so far" : "");
    }
    stats.push_back(es);
    const bool stop = stopper.stop(epoch);  // identical on every rank: from broadcast figures
    // The other ranks hold identical weights: one writer is enough. Failure mode: if a write here
    // throws on rank 0 (disk full, permissions), the other ranks do not know and wait in the next
    // collective (the cache refresh or the validation) until the process-group timeout, then fail
    // with a generic "lost a rank" error; rank 0's own message is the one that names the cause.
    if (lead) {
      spdlog::info("epoch {}: loss {:.4f}, active negatives {:.1f} %, lr {:.3g}, {:.0f} s", epoch, es.loss,
                   100 * es.active, es.lr, es.seconds);
      // Everything to .tmp files first (the slow part), then renamed into place back to back, .epoch
      // last: a kill while writing leaves the previous epoch's complete set; only a kill between the
      // renames (microseconds) could mix two epochs.
      const fs::path epoch_file = ckpt.string() + ".epoch", optim_file = ckpt.string() + ".optim";
      save_model(model, tmp_path(ckpt));
      torch::save(*opt, tmp_path(optim_file).string());
      if (improved) save_model(model, tmp_path(best_file));
      write_checkpoint_state(tmp_path(epoch_file), {epoch, stopper.best_epoch(), stopper.best()});
      // The log before the renames: a resumed run keeps only the rows up to the epoch .epoch names,
      // so a row of an epoch whose checkpoint never landed is dropped.
      log_rows.push_back(es);
      write_training_log(o.out, log_rows);
      fs::rename(tmp_path(ckpt), ckpt);
      fs::rename(tmp_path(optim_file), optim_file);
      if (improved) fs::rename(tmp_path(best_file), best_file);
      fs::rename(tmp_path(epoch_file), epoch_file);
    }
    if (stop) {
      if (lead)
        spdlog::info(
            "early stop after epoch {}: val R@1 has not improved for {} epochs (best {:.3f} at epoch {})",
            epoch, o.patience, stopper.best(), stopper.best_epoch());
      break;
    }
  }
  if (lead) {
    if (!val.sets.empty() && stopper.best_epoch() > 0) {
      fs::copy_file(best_file, o.out, fs::copy_options::overwrite_existing);
      spdlog::info("wrote {}: the weights of epoch {}, the best val R@1 ({:.3f})", o.out.string(),
                   stopper.best_epoch(), stopper.best());
    } else {
      save_model(model, o.out);
      spdlog::info("wrote {} (the last epoch's weights)", o.out.string());
    }
  }
  return stats;
}

}  // namespace sp::place
