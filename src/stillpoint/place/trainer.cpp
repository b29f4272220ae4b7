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
  need(o.patience >= 0, fmt::format("patience must be >= 0, not {}", o.patience));
  need(o.patience == 0 || !o.val.empty(), "--patience needs --val (early stopping watches the val recall)");
  validate(o.lr_schedule);
  validate(o.augment);
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

// Every image resized to the model input, RGB, uint8 (N,3,H,W), held in memory on every rank:
// 3·H·W bytes per image, 230 KB at 240×320, so the full training set of 40 rooms × 400 views
// (16 000 images) takes about 3.7 GB per rank (plus the val images).
torch::Tensor load_images(const std::vector<fs::path>& files, int h, int w, bool progress, const char* what) {
  auto store = torch::empty({static_cast<int64_t>(files.size()), 3, h, w}, torch::kUInt8);
  sp::ProgressBar bar(what, files.size(), progress);
  for (size_t i = 0; i < files.size(); ++i) {
    const cv::Mat bgr = cv::imread(files[i].string(), cv::IMREAD_COLOR);
    if (bgr.empty()) throw sp::InputError(files[i].string(), 0, "cannot read image");
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

ValData load_val(const TrainOptions& o, int h, int w, bool lead) {
  ValData v;
  if (o.val.empty()) return v;
  std::vector<fs::path> files;
  for (const auto& dir : o.val) {
    const auto set = load_retrieval_set(dir, o.rules);
    if (set.queries.empty())
      throw sp::InputError(dir.string(), 0, "--val set has no query with a true match");
    ValData::Set s{dir.string(), static_cast<int64_t>(files.size()), static_cast<int64_t>(set.queries.size()),
                   static_cast<int64_t>(set.database.size()), set.ground_truth};
    files.insert(files.end(), set.queries.begin(), set.queries.end());
    files.insert(files.end(), set.database.begin(), set.database.end());
    if (lead)
      spdlog::info("val {}: {} queries, {} database images ({})", s.dir, s.queries, s.database, set.name);
    v.sets.push_back(std::move(s));
  }
  v.store = load_images(files, h, w, o.progress && lead, "loading val images");
  return v;
}

// Recall@N pooled over the val sets (each query counts once). Every rank describes its share and the
// sum gives all ranks the same descriptors; rank 0's figures are then broadcast anyway, so that the
// early-stopping and best-epoch decisions are identical by construction, not by float agreement.
RecallResult evaluate_val(ParCNetVLAD& model, const ValData& v, ProcessGroup& pg) {
  const auto desc = describe_all(model, v.store, 32, pg).contiguous();
  const int64_t dim = desc.size(1);
  using RowMajor = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  const auto rows = [&](int64_t first, int64_t n) -> Eigen::MatrixXf {
    return Eigen::Map<const RowMajor>(desc.data_ptr<float>() + first * dim, n, dim);
  };
  auto hits = torch::zeros({static_cast<int64_t>(RecallResult::kN.size()) + 1}, torch::kFloat64);
  for (const auto& s : v.sets) {
    const auto r = recall_at_n(
        sp::place::squared_distances(rows(s.first, s.queries), rows(s.first + s.queries, s.database)),
        s.ground_truth);
    for (size_t k = 0; k < RecallResult::kN.size(); ++k)
      hits[static_cast<int64_t>(k)] += r.recall[k] * static_cast<double>(r.queries);
    hits[static_cast<int64_t>(RecallResult::kN.size())] += r.queries;
  }
  pg.broadcast(hits, 0, "the validation broadcast");
  RecallResult out;
  out.queries = static_cast<int>(hits[static_cast<int64_t>(RecallResult::kN.size())].item<double>());
  for (size_t k = 0; k < RecallResult::kN.size(); ++k)
    out.recall[k] = out.queries > 0 ? hits[static_cast<int64_t>(k)].item<double>() / out.queries : 0.0;
  return out;
}

// Augments a training batch in place: row r of `batch` (uint8 N,3,H,W) with keys[r].
void augment_batch(torch::Tensor& batch, const AugmentOptions& o, const std::vector<AugmentKey>& keys) {
  if (!o.enabled) return;
  const int h = static_cast<int>(batch.size(2)), w = static_cast<int>(batch.size(3));
  for (int64_t r = 0; r < batch.size(0); ++r) {
    const auto hwc = batch[r].permute({1, 2, 0}).contiguous();
    const cv::Mat in(h, w, CV_8UC3, hwc.data_ptr<uint8_t>());
    cv::Mat out = augment_image(in, o, keys[static_cast<size_t>(r)]);
    batch[r].copy_(torch::from_blob(out.data, {h, w, 3}, torch::kUInt8).permute({2, 0, 1}));
  }
}

void set_lr(torch::optim::Optimizer& opt, double lr) {
  for (auto& g : opt.param_groups()) g.options().set_lr(lr);
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
  } else {
    model = ParCNetVLAD(o.model);
  }
  const int start_epoch = resumed.epoch;
  if (lead) spdlog::info("model: {}", model->cfg.summary());
  std::vector<fs::path> files;
  for (const auto& im : imgs) files.push_back(im.file);
  const auto store =
      load_images(files, model->cfg.input_height, model->cfg.input_width, progress, "loading images");
  const ValData val = load_val(o, model->cfg.input_height, model->cfg.input_width, lead);
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
  if (o.resume.empty() && lead) init_centroids(model, store, o.kmeans_images, rng);
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
