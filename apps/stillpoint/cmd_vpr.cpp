// `stillpoint vpr`: train and evaluate the ParC_NetVLAD place descriptor, and the BoW baseline.
#include <spdlog/spdlog.h>

#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <optional>

#include "commands.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/common/progress_bar.hpp"
#include "stillpoint/common/timing.hpp"
#include "stillpoint/place/bow.hpp"
#include "stillpoint/place/descriptor.hpp"
#include "stillpoint/place/distill.hpp"
#include "stillpoint/place/retrieval.hpp"
#include "stillpoint/place/trainer.hpp"

namespace sp::app {

namespace {

namespace fs = std::filesystem;
using sp::place::RetrievalSet;

// The architecture options shared by `vpr train` and `vpr distill`.
struct ModelArgs {
  std::string variant = "small", parc = "on", cbam = "on", config;
  double width_mult = 0, depth_mult = 0;
  int input_h = 0, input_w = 0, clusters = 0;
};

struct TrainArgs {
  sp::place::TrainOptions o;
  ModelArgs m;
  int world_size = 0, rank = -1;  // unset (0, -1): torchrun's WORLD_SIZE / RANK, else one process
  std::string master;             // HOST:PORT; empty: MASTER_ADDR / MASTER_PORT
  std::string augment = "on", lr_schedule = "cosine";
};

struct DistillArgs {
  sp::place::DistillOptions o;
  ModelArgs m;
  std::string augment = "on", center = "on";
};

struct EvalArgs {
  fs::path model, bow, dataset, json;
  int threads = 2;
  bool progress = true;
};

struct BowArgs {
  std::vector<fs::path> data;
  fs::path out;
  int words = 1000, images = 400, features = 500;
  std::uint64_t seed = 1;
};

cv::Mat read_image(const fs::path& p) {
  cv::Mat im = cv::imread(p.string(), cv::IMREAD_COLOR);
  if (im.empty()) throw sp::InputError(p.string(), 0, "cannot read image");
  return im;
}

std::optional<std::string> env(const char* name) {
  const char* v = std::getenv(name);
  return v && *v ? std::optional<std::string>(v) : std::nullopt;
}

int to_int(const std::string& text, const std::string& what) {
  size_t used = 0;
  int v = 0;
  try {
    v = std::stoi(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != text.size()) throw sp::Error(what + " must be an integer, not '" + text + "'");
  return v;
}

// Flags win; otherwise the variables torchrun sets (WORLD_SIZE, RANK, MASTER_ADDR, MASTER_PORT), so a
// launcher that exports them per process needs no flags; otherwise a single process.
void resolve_distributed(TrainArgs& a) {
  auto& o = a.o.dist;
  const auto ws = env("WORLD_SIZE"), rk = env("RANK");
  o.world_size = a.world_size > 0 ? a.world_size : ws ? to_int(*ws, "WORLD_SIZE") : 1;
  o.rank = a.rank >= 0 ? a.rank : rk ? to_int(*rk, "RANK") : 0;
  if (!a.master.empty()) {
    const auto colon = a.master.rfind(':');
    if (colon == std::string::npos || colon == 0)
      throw sp::Error("--master must be HOST:PORT (rank 0's address), not '" + a.master + "'");
    o.master_addr = a.master.substr(0, colon);
    if (o.master_addr.size() > 2 && o.master_addr.front() == '[' && o.master_addr.back() == ']')
      o.master_addr = o.master_addr.substr(1, o.master_addr.size() - 2);  // [IPv6]:port
    o.master_port = to_int(a.master.substr(colon + 1), "the port of --master");
  } else if (o.world_size > 1) {
    const auto addr = env("MASTER_ADDR"), port = env("MASTER_PORT");
    if (!addr || !port)
      throw sp::Error(
          "a world size above 1 needs rank 0's address: --master HOST:PORT, or MASTER_ADDR and "
          "MASTER_PORT in the environment");
    o.master_addr = *addr;
    o.master_port = to_int(*port, "MASTER_PORT");
  }
  if (o.world_size > 1 && o.rank == 0 && !a.o.resume.empty())
    spdlog::info("resuming on every rank: each needs {} and its .epoch/.optim files", a.o.resume.string());
}

sp::place::ModelConfig build_model(const ModelArgs& a) {
  auto m = a.variant == "tiny" ? sp::place::ModelConfig::tiny() : sp::place::ModelConfig::small();
  if (!a.config.empty()) {
    const auto r = sp::ConfigReader::from_file(a.config);
    m = sp::place::ModelConfig::from_yaml(r);
    r.finish();
  }
  if (a.width_mult > 0 || a.depth_mult > 0) {
    m = sp::place::ModelConfig::scaled(m, a.width_mult > 0 ? a.width_mult : 1.0,
                                       a.depth_mult > 0 ? a.depth_mult : 1.0);
  }
  if (a.input_h > 0) m.input_height = a.input_h;
  if (a.input_w > 0) m.input_width = a.input_w;
  if (a.clusters > 0) m.clusters = a.clusters;
  m.parc = a.parc == "on";
  m.cbam = a.cbam == "on";
  return m;
}

void add_model_options(CLI::App* cmd, ModelArgs& m) {
  cmd->add_option("--variant", m.variant)->check(CLI::IsMember({"small", "tiny"}))->capture_default_str();
  cmd->add_option("--config", m.config, "YAML model config (ModelConfig::from_yaml keys)");
  cmd->add_option("--parc", m.parc)->check(CLI::IsMember({"on", "off"}))->capture_default_str();
  cmd->add_option("--cbam", m.cbam)->check(CLI::IsMember({"on", "off"}))->capture_default_str();
  cmd->add_option("--width-mult", m.width_mult, "scale the variant's widths")->check(CLI::Range(0.05, 2.0));
  cmd->add_option("--depth-mult", m.depth_mult, "scale the variant's depths")->check(CLI::Range(0.1, 2.0));
  cmd->add_option("--input-height", m.input_h)->check(CLI::Range(32, 2048));
  cmd->add_option("--input-width", m.input_w)->check(CLI::Range(32, 2048));
  cmd->add_option("--clusters", m.clusters)->check(CLI::Range(2, 512));
}

void run_distill(DistillArgs& a) {
  a.o.model = build_model(a.m);
  a.o.augment.enabled = a.augment == "on";
  a.o.center_targets = a.center == "on";
  sp::place::distill_model(a.o);
}

void run_train(TrainArgs& a) {
  auto& o = a.o;
  resolve_distributed(a);
  o.model = build_model(a.m);
  o.augment.enabled = a.augment == "on";
  o.lr_schedule.kind = sp::place::parse_lr_schedule(a.lr_schedule);
  // train_model refuses a --val room that is also trained on and writes the log files (rank 0).
  sp::place::train_model(o);
}

// Ranks the database for each query and scores Recall@1/5/10/20; writes JSON when asked.
void run_eval(const EvalArgs& a) {
  const RetrievalSet set = sp::place::load_retrieval_set(a.dataset);
  spdlog::info("{}: {} queries, {} database images ({}){}", set.name, set.queries.size(), set.database.size(),
               set.rule,
               set.dropped_queries > 0 ? fmt::format(", {} queries dropped", set.dropped_queries) : "");
  Eigen::MatrixXf dist;
  std::vector<double> ms;
  std::string method;
  const auto all = [&] {
    std::vector<fs::path> v = set.queries;
    v.insert(v.end(), set.database.begin(), set.database.end());
    return v;
  }();
  sp::ProgressBar bar("describing", all.size(), a.progress);
  if (!a.model.empty()) {
    method = "ParC_NetVLAD " + a.model.filename().string();
    auto ex = sp::place::PlaceDescriptorExtractor::load(a.model, a.threads);
    Eigen::MatrixXf desc(static_cast<Eigen::Index>(all.size()), ex.dimension());
    for (size_t i = 0; i < all.size(); ++i) {
      const cv::Mat im = read_image(all[i]);
      sp::Stopwatch sw;
      desc.row(static_cast<Eigen::Index>(i)) = ex.describe(im).transpose();
      ms.push_back(sw.elapsed_ms());
      if (i % 50 == 0) bar.update(i + 1);
    }
    const auto nq = static_cast<Eigen::Index>(set.queries.size());
    dist = sp::place::squared_distances(desc.topRows(nq), desc.bottomRows(desc.rows() - nq));
  } else if (!a.bow.empty()) {
    method = "BoW (ORB)";
    const auto voc = sp::place::BowVocabulary::load(a.bow);
    std::vector<Eigen::VectorXf> v;
    for (size_t i = 0; i < all.size(); ++i) {
      const cv::Mat im = read_image(all[i]);
      sp::Stopwatch sw;
      v.push_back(voc.transform(sp::place::orb_descriptors(im)));
      ms.push_back(sw.elapsed_ms());
      if (i % 50 == 0) bar.update(i + 1);
    }
    const size_t nq = set.queries.size();
    dist.resize(static_cast<Eigen::Index>(nq), static_cast<Eigen::Index>(set.database.size()));
    for (size_t q = 0; q < nq; ++q) {
      for (size_t d = 0; d < set.database.size(); ++d) {
        dist(static_cast<Eigen::Index>(q), static_cast<Eigen::Index>(d)) =
            1.0f - sp::place::BowVocabulary::score(v[q], v[nq + d]);
      }
    }
  } else {
    throw sp::Error("vpr eval: give --model or --bow");
  }
  bar.finish();
  const auto r = sp::place::recall_at_n(dist, set.ground_truth);
  const auto t = sp::summarize(ms);
  spdlog::info("{} on {}: R@1 {:.3f} R@5 {:.3f} R@10 {:.3f} R@20 {:.3f} ({} queries), {:.1f} ms/image",
               method, set.name, r.recall[0], r.recall[1], r.recall[2], r.recall[3], r.queries, t.mean);
  if (!a.json.empty()) {
    nlohmann::json j = {{"method", method},
                        {"dataset", a.dataset.string()},
                        {"set", set.name},
                        {"rule", set.rule},
                        {"recall@1", r.recall[0]},
                        {"recall@5", r.recall[1]},
                        {"recall@10", r.recall[2]},
                        {"recall@20", r.recall[3]},
                        {"queries", r.queries},
                        {"dropped_queries", set.dropped_queries},
                        {"database", set.database.size()},
                        {"ms_per_image", t.mean},
                        {"ms_per_image_median", t.median}};
    if (a.json.has_parent_path()) fs::create_directories(a.json.parent_path());
    std::ofstream(a.json) << j.dump(2) << "\n";
  }
}

void run_bow_train(const BowArgs& a) {
  const auto imgs = sp::place::collect_places(a.data);
  // Evenly spaced images so that every room contributes.
  const size_t step = std::max<size_t>(1, imgs.size() / static_cast<size_t>(a.images));
  std::vector<cv::Mat> desc;
  for (size_t i = 0; i < imgs.size(); i += step)
    desc.push_back(sp::place::orb_descriptors(read_image(imgs[i].file), a.features));
  spdlog::info("BoW: {} words from {} images", a.words, desc.size());
  const auto voc = sp::place::BowVocabulary::train(desc, a.words, 8, a.seed);
  voc.save(a.out);
  spdlog::info("wrote {}", a.out.string());
}

}  // namespace

void add_vpr_command(CLI::App& app) {
  auto* vpr = app.add_subcommand("vpr", "ParC_NetVLAD place recognition: train, eval, bow-train");
  vpr->require_subcommand(1);

  auto ta = std::make_shared<TrainArgs>();
  auto* train = vpr->add_subcommand("train", "train on dynsynth places folders");
  train->add_option("--data", ta->o.data, "places folders (or folders of them)")->required()->expected(1, -1);
  train->add_option("--out", ta->o.out, "model file to write")->required();
  add_model_options(train, ta->m);
  train->add_option("--epochs", ta->o.epochs)->check(CLI::Range(1, 1000))->capture_default_str();
  train->add_option("--lr", ta->o.lr)->check(CLI::Range(1e-7, 1.0))->capture_default_str();
  train->add_option("--lr-schedule", ta->lr_schedule, "per-step learning-rate schedule after the warm-up")
      ->check(CLI::IsMember({"constant", "cosine", "step"}))
      ->capture_default_str();
  train->add_option("--warmup-epochs", ta->o.lr_schedule.warmup_epochs, "linear warm-up (0: none)")
      ->check(CLI::Range(0.0, 1000.0))
      ->capture_default_str();
  train
      ->add_option("--lr-step-epochs", ta->o.lr_schedule.step_epochs,
                   "step schedule: epochs between decays (0: a third of the run)")
      ->check(CLI::Range(0, 1000))
      ->capture_default_str();
  train->add_option("--lr-gamma", ta->o.lr_schedule.step_gamma, "step schedule: factor per decay")
      ->check(CLI::Range(1e-6, 1.0))
      ->capture_default_str();
  train->add_option("--augment", ta->augment, "colour, exposure, blur, noise and crop augmentation")
      ->check(CLI::IsMember({"on", "off"}))
      ->capture_default_str();
  train->add_option("--val", ta->o.val, "held-back places folders: recall per epoch, best epoch kept")
      ->expected(1, -1);
  train->add_option("--patience", ta->o.patience, "stop after N epochs without a better val R@1 (0: never)")
      ->check(CLI::Range(0, 1000))
      ->capture_default_str();
  train->add_option("--optimizer", ta->o.optimizer)
      ->check(CLI::IsMember({"adam", "sgd"}))
      ->capture_default_str();
  train->add_option("--margin", ta->o.margin)->check(CLI::Range(0.0, 4.0))->capture_default_str();
  train->add_option("--negatives", ta->o.negatives)->check(CLI::Range(1, 50))->capture_default_str();
  train->add_option("--negative-pool", ta->o.negative_pool)
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  train
      ->add_option("--negative-distance", ta->o.rules.negative_distance,
                   "m: a view of the same room counts as a negative beyond this (another room always does)")
      ->check(CLI::Range(0.5, 1e6))
      ->capture_default_str();
  train
      ->add_option("--negative-min-angle", ta->o.rules.negative_min_angle_deg,
                   "deg: same-room negatives must also be rotated this much (0: distance alone)")
      ->check(CLI::Range(0.0, 180.0))
      ->capture_default_str();
  train->add_option("--queries-per-epoch", ta->o.queries_per_epoch)
      ->check(CLI::Range(1, 1000000))
      ->capture_default_str();
  train->add_option("--batch", ta->o.batch)->check(CLI::Range(1, 256))->capture_default_str();
  train->add_option("--refresh-every", ta->o.refresh_every, "queries between cache refreshes")
      ->check(CLI::Range(1, 1000000))
      ->capture_default_str();
  train->add_option("--kmeans-images", ta->o.kmeans_images)
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  train->add_option("--seed", ta->o.seed)->capture_default_str();
  train->add_option("--resume", ta->o.resume, "checkpoint (<out>.ckpt) to continue from");
  train->add_option("--init", ta->o.init,
                    "model to start from, e.g. from vpr distill (architecture and NetVLAD from the file)");
  train->add_option("--threads", ta->o.threads)->check(CLI::Range(1, 2))->capture_default_str();
  train->add_flag("!--no-progress", ta->o.progress, "no progress bar");
  train
      ->add_option("--world-size", ta->world_size,
                   "processes training together (default: $WORLD_SIZE, else 1)")
      ->check(CLI::Range(1, 4096));
  train->add_option("--rank", ta->rank, "this process's rank, 0 to world size - 1 (default: $RANK, else 0)")
      ->check(CLI::Range(0, 4095));
  train->add_option("--master", ta->master,
                    "HOST:PORT where rank 0 listens (default: $MASTER_ADDR:$MASTER_PORT)");
  train
      ->add_option("--dist-timeout", ta->o.dist.timeout_s,
                   "seconds before a silent (dead or stalled) rank fails the others")
      ->check(CLI::Range(1.0, 86400.0))
      ->capture_default_str();
  train->callback([ta] { run_train(*ta); });

  auto da = std::make_shared<DistillArgs>();
  auto* distill = vpr->add_subcommand(
      "distill",
      "initialise the backbone by distilling a pretrained teacher's features, then NetVLAD by k-means");
  distill->add_option("--data", da->o.data, "places folders (or folders of them)")
      ->required()
      ->expected(1, -1);
  distill->add_option("--out", da->o.out, "model file to write")->required();
  distill
      ->add_option("--teacher", da->o.teacher,
                   "teacher network (ONNX), e.g. models/yolox_nano/yolox_nano.onnx")
      ->required();
  distill
      ->add_option("--teacher-mid", da->o.teacher_mid, "teacher layer for the student's stage 3 (\"\": none)")
      ->capture_default_str();
  distill->add_option("--teacher-top", da->o.teacher_top, "teacher layer for the NetVLAD input (\"\": none)")
      ->capture_default_str();
  distill->add_option("--teacher-size", da->o.teacher_size, "square teacher input, px")
      ->check(CLI::Range(32, 4096))
      ->capture_default_str();
  distill->add_option("--top-weight", da->o.top_weight, "weight of the NetVLAD-input level")
      ->check(CLI::Range(0.0, 100.0))
      ->capture_default_str();
  distill
      ->add_option("--center-targets", da->center,
                   "subtract the teacher's per-channel mean before the cosine")
      ->check(CLI::IsMember({"on", "off"}))
      ->capture_default_str();
  add_model_options(distill, da->m);
  distill->add_option("--steps", da->o.steps)->check(CLI::Range(1, 10000000))->capture_default_str();
  distill->add_option("--batch", da->o.batch)->check(CLI::Range(1, 1024))->capture_default_str();
  distill->add_option("--lr", da->o.lr, "Adam; 5 % warm-up, then cosine to 1 %")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  distill->add_option("--max-images", da->o.max_images, "images with cached teacher features (0: all)")
      ->check(CLI::Range(0, 10000000))
      ->capture_default_str();
  distill->add_option("--kmeans-images", da->o.kmeans_images)
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  distill->add_option("--augment", da->augment, "colour, exposure, blur and noise on the student's input")
      ->check(CLI::IsMember({"on", "off"}))
      ->capture_default_str();
  distill->add_option("--val", da->o.val, "held-back places folders: recall of the result")->expected(1, -1);
  distill->add_option("--eval-every", da->o.eval_every, "steps between val evaluations (0: at the end only)")
      ->check(CLI::Range(0, 10000000))
      ->capture_default_str();
  distill->add_option("--seed", da->o.seed)->capture_default_str();
  distill->add_option("--threads", da->o.threads)->check(CLI::Range(1, 2))->capture_default_str();
  distill->add_flag("!--no-progress", da->o.progress, "no progress bar");
  distill->callback([da] { run_distill(*da); });

  auto ea = std::make_shared<EvalArgs>();
  auto* eval = vpr->add_subcommand("eval", "Recall@1/5/10/20 on a place-recognition set");
  eval->add_option("--model", ea->model, "ParC_NetVLAD model file");
  eval->add_option("--bow", ea->bow, "BoW vocabulary (from vpr bow-train) instead of a model");
  eval->add_option("--dataset", ea->dataset, "nordland/, corridor/ or dynsynth places folder(s)")->required();
  eval->add_option("--json", ea->json, "write the figures as JSON");
  eval->add_option("--threads", ea->threads)->check(CLI::Range(1, 2))->capture_default_str();
  eval->add_flag("!--no-progress", ea->progress, "no progress bar");
  eval->callback([ea] { run_eval(*ea); });

  auto ba = std::make_shared<BowArgs>();
  auto* bow = vpr->add_subcommand("bow-train", "train the flat ORB vocabulary of the BoW baseline");
  bow->add_option("--data", ba->data)->required()->expected(1, -1);
  bow->add_option("--out", ba->out)->required();
  bow->add_option("--words", ba->words)->check(CLI::Range(16, 100000))->capture_default_str();
  bow->add_option("--images", ba->images)->check(CLI::Range(1, 100000))->capture_default_str();
  bow->add_option("--seed", ba->seed)->capture_default_str();
  bow->callback([ba] { run_bow_train(*ba); });
}

}  // namespace sp::app
