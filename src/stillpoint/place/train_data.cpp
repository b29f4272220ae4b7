#include "stillpoint/place/train_data.hpp"

#include <spdlog/spdlog.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <numeric>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "stillpoint/common/error.hpp"
#include "stillpoint/common/progress_bar.hpp"

namespace sp::place::detail {

namespace fs = std::filesystem;

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

ValData load_val(const std::vector<fs::path>& dirs, const PlaceRules& rules, int h, int w, bool lead,
                 bool progress) {
  ValData v;
  if (dirs.empty()) return v;
  std::vector<fs::path> files;
  for (const auto& dir : dirs) {
    const auto set = load_retrieval_set(dir, rules);
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
  v.store = load_images(files, h, w, progress, "loading val images");
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

}  // namespace sp::place::detail
