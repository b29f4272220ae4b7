// `stillpoint vocab train|info`: builds the ORB bag-of-words vocabulary and inspects vocabulary files.
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <Eigen/Geometry>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <opencv2/imgcodecs.hpp>
#include <sstream>

#include "commands.hpp"
#include "stillpoint/common/data_dir.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/common/timing.hpp"
#include "stillpoint/features/orb_extractor.hpp"
#include "stillpoint/loop/loop_detector.hpp"
#include "stillpoint/loop/vocab_trainer.hpp"

namespace sp::app {
namespace {

// `timestamp rest...` lines of a TUM text file, '#' comments skipped.
std::vector<std::pair<double, std::string>> read_stamped(const std::filesystem::path& file) {
  std::ifstream in(file);
  if (!in) throw sp::InputError(file.string(), 0, "cannot open");
  std::vector<std::pair<double, std::string>> out;
  std::string line;
  int n = 0;
  while (std::getline(in, line)) {
    ++n;
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ss(line);
    double t = 0;
    if (!(ss >> t)) throw sp::InputError(file.string(), n, "expected a timestamp");
    std::string rest;
    std::getline(ss, rest);
    out.emplace_back(t, rest);
  }
  return out;
}

struct Pose {
  Eigen::Quaterniond q_wc;
  Eigen::Vector3d t_wc;
};

// A loop-detection dry run on a TUM sequence: keyframes every N frames, camera rotations and the
// "map" covisibility (temporal window) taken from the ground truth, candidates judged by the
// ground-truth distance between the two keyframes. Compares the per-keyframe and sequence detectors.
void evaluate_loops(const std::filesystem::path& seq, const std::filesystem::path& vocab_file, int every,
                    int window) {
  const auto vocab = sp::loop::Vocabulary::load(vocab_file);
  const auto rgb = read_stamped(seq / "rgb.txt");
  std::map<double, Pose> gt;
  for (const auto& [t, rest] : read_stamped(seq / "groundtruth.txt")) {
    std::istringstream ss(rest);
    Pose p;
    double qx, qy, qz, qw;
    ss >> p.t_wc.x() >> p.t_wc.y() >> p.t_wc.z() >> qx >> qy >> qz >> qw;
    p.q_wc = Eigen::Quaterniond(qw, qx, qy, qz).normalized();
    gt[t] = p;
  }
  sp::feat::OrbExtractor orb(sp::feat::OrbConfig{});
  std::vector<sp::loop::KeyframeInfo> kfs;
  std::vector<Pose> poses;
  std::vector<double> transform_ms;
  for (std::size_t i = 0; i < rgb.size(); i += static_cast<std::size_t>(every)) {
    const auto it = gt.lower_bound(rgb[i].first);
    if (it == gt.end() || std::abs(it->first - rgb[i].first) > 0.02) continue;
    std::string path = rgb[i].second;
    path.erase(0, path.find_first_not_of(' '));
    const cv::Mat gray = cv::imread((seq / path).string(), cv::IMREAD_GRAYSCALE);
    if (gray.empty()) throw sp::InputError((seq / path).string(), 0, "cannot read the image");
    std::vector<cv::KeyPoint> kps;
    cv::Mat desc;
    orb.extract(gray, kps, desc);
    sp::loop::KeyframeInfo kf;
    kf.id = sp::loop::KeyframeId{kfs.size()};  // the keyframe's index: poses[id]
    kf.R_cw = it->second.q_wc.toRotationMatrix().transpose();
    sp::Stopwatch sw;
    kf.bow = vocab.transform(desc);
    transform_ms.push_back(sw.elapsed_ms());
    if (!kfs.empty()) {
      spdlog::debug("kf {}: {} words, rotation from previous {:.3f} rad", kf.id, kf.bow.size(),
                    sp::loop::rotation_angle(kfs.back().R_cw, kf.R_cw));
    }
    kfs.push_back(std::move(kf));
    poses.push_back(it->second);
  }
  spdlog::info("{} keyframes, BoW transform {:.2f} ms median per image", kfs.size(),
               sp::summarize(transform_ms).median);
  struct Window final : sp::loop::CovisibilityView {
    int w = 0;
    sp::loop::KeyframeId newest;
    [[nodiscard]] std::vector<sp::loop::KeyframeId> covisible(sp::loop::KeyframeId id,
                                                              int n_best) const override {
      std::vector<sp::loop::KeyframeId> out;
      const auto n = id.value();
      for (std::uint64_t d = 1; d <= static_cast<std::uint64_t>(w); ++d) {
        if (n >= d) out.emplace_back(n - d);
        if (n + d <= newest.value()) out.emplace_back(n + d);
      }
      if (n_best > 0 && out.size() > static_cast<std::size_t>(n_best))
        out.resize(static_cast<std::size_t>(n_best));
      return out;
    }
  } view;
  view.w = window;
  // Per keyframe, then keyframe sequences with both readings of Algorithm 1 (docs/loop_sequences.md).
  const std::vector<std::pair<std::string, std::string>> detectors = {
      {"bow-keyframe", ""}, {"bow-sequence", "rising-edge"}, {"bow-sequence", "level"}};
  for (const auto& [method_name, trigger] : detectors) {
    sp::loop::LoopDetectorParams params;
    if (!trigger.empty()) params.sequence.trigger = trigger;
    const std::string method = trigger.empty() ? method_name : method_name + "/" + trigger;
    auto det = sp::loop::make_loop_detector(method_name, params);
    std::vector<double> ms;
    std::size_t good = 0, bad = 0;
    std::string first = "none";
    for (const auto& kf : kfs) {
      view.newest = kf.id;
      sp::Stopwatch sw;
      const auto cands = det->detect(kf, view);
      ms.push_back(sw.elapsed_ms());
      for (const auto& c : cands) {
        const Pose& a = poses[c.query.value()];
        const Pose& b = poses[c.match.value()];
        const bool ok = (a.t_wc - b.t_wc).norm() < 0.5 && a.q_wc.angularDistance(b.q_wc) < 0.5;
        (ok ? good : bad) += 1;
        spdlog::debug("{} candidate q {} m {} score {:.3f}: {:.2f} m, {:.2f} rad apart", method, c.query,
                      c.match, c.score, (a.t_wc - b.t_wc).norm(), a.q_wc.angularDistance(b.q_wc));
        if (first == "none") first = std::to_string(kf.id.value());
      }
    }
    for (const auto& c : det->finish(view)) {
      const Pose& a = poses[c.query.value()];
      const Pose& b = poses[c.match.value()];
      const bool ok = (a.t_wc - b.t_wc).norm() < 0.5 && a.q_wc.angularDistance(b.q_wc) < 0.5;
      (ok ? good : bad) += 1;
      spdlog::debug("{} final candidate q {} m {}: {:.2f} m apart", method, c.query, c.match,
                    (a.t_wc - b.t_wc).norm());
      if (first == "none") first = "end";
    }
    const auto st = det->stats();
    const auto sum = sp::summarize(ms);
    spdlog::info(
        "{:25s} keyframes {} queries {} scored pairs {} candidates {} (GT-correct {}, wrong {}), first at kf "
        "{}, "
        "detect total {:.2f} ms, mean {:.3f} ms/kf",
        method, st.keyframes, st.queries, st.scored_pairs, st.candidates, good, bad, first, sum.total,
        sum.mean);
  }
}

}  // namespace

void add_vocab_command(CLI::App& app) {
  auto* vocab = app.add_subcommand("vocab", "Train or inspect the ORB bag-of-words vocabulary");
  vocab->require_subcommand(1);

  auto opts = std::make_shared<sp::loop::VocabTrainingOptions>();
  auto out = std::make_shared<std::string>();
  auto* train = vocab->add_subcommand("train", "Train a vocabulary tree on folders of images");
  train->add_option("--images", opts->inputs, "image folders or TUM sequence folders (uses rgb/)")
      ->required()
      ->check(CLI::ExistingDirectory);
  train->add_option("--out", *out, "output vocabulary file (.spv)")->required();
  train->add_option("--k", opts->vocabulary.k, "branching factor")
      ->capture_default_str()
      ->check(CLI::Range(2, 32));
  train->add_option("--levels", opts->vocabulary.levels, "tree depth")
      ->capture_default_str()
      ->check(CLI::Range(1, 8));
  train->add_option("--max-images", opts->max_images, "use at most N images, evenly spaced (0 = all)")
      ->capture_default_str();
  train->add_option("--features", opts->features, "ORB features per image")
      ->capture_default_str()
      ->check(CLI::Range(100, 10000));
  train->add_option("--seed", opts->seed, "random seed of the k-means++ seeding")->capture_default_str();
  train->callback([opts, out] {
    sp::loop::VocabTrainingReport rep;
    const sp::loop::Vocabulary v = sp::loop::train_vocabulary(*opts, &rep);
    const std::filesystem::path file(*out);
    if (file.has_parent_path()) std::filesystem::create_directories(file.parent_path());
    v.save(file);
    spdlog::info("vocab: {} images, {} descriptors, ORB {:.1f} s, training {:.1f} s", rep.images,
                 rep.descriptors, rep.extract_s, rep.train_s);
    spdlog::info("vocab: {} words, {} nodes (k={}, L={}), {:.2f} MB -> {}", v.size(), v.node_count(),
                 v.branching(), v.levels(), static_cast<double>(std::filesystem::file_size(file)) / 1e6,
                 file.string());
  });

  auto file = std::make_shared<std::string>();
  auto* info = vocab->add_subcommand("info", "Print a vocabulary's size, shape and load time");
  info->add_option("file", *file, "vocabulary file (.spv)")->required();
  info->callback([file] {
    sp::Stopwatch sw;
    const sp::loop::Vocabulary v = sp::loop::Vocabulary::load(*file);
    const double ms = sw.elapsed_ms();
    std::size_t weighted = 0;
    for (std::uint32_t w = 0; w < v.size(); ++w) weighted += v.word_weight(w) > 0.0 ? 1 : 0;
    spdlog::info("{}: {} words ({} with weight > 0), {} nodes, k={}, L={}, {:.2f} MB, loaded in {:.1f} ms",
                 *file, v.size(), weighted, v.node_count(), v.branching(), v.levels(),
                 static_cast<double>(std::filesystem::file_size(*file)) / 1e6, ms);
  });

  auto seq = std::make_shared<std::string>();
  auto vfile = std::make_shared<std::string>();  // default: the shipped vocabulary in the data folder
  auto every = std::make_shared<int>(10);
  auto window = std::make_shared<int>(10);
  auto* loops =
      vocab->add_subcommand("loops",
                            "Dry-run the loop detectors on a TUM sequence (ground-truth poses): per "
                            "keyframe, and keyframe sequences with both readings of Algorithm 1");
  loops->add_option("--sequence", *seq, "TUM sequence folder (rgb.txt, groundtruth.txt)")->required();
  loops->add_option("--vocab", *vfile, "vocabulary file (default: DATA/data/vocab/stillpoint_orb.spv)");
  loops->add_option("--every", *every, "a keyframe every N frames")
      ->capture_default_str()
      ->check(CLI::Range(1, 1000));
  loops->add_option("--window", *window, "keyframes this close in time count as covisible")
      ->capture_default_str()
      ->check(CLI::Range(1, 1000));
  loops->callback([=] {
    const std::string vocab_file =
        vfile->empty()
            ? (sp::resolve_data_dir(sp::current_executable()) / "data" / "vocab" / "stillpoint_orb.spv")
                  .string()
            : *vfile;
    evaluate_loops(*seq, vocab_file, *every, *window);
  });
}

}  // namespace sp::app
