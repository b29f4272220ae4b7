// `stillpoint vocab train|info`: builds the ORB bag-of-words vocabulary and inspects vocabulary files.
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <filesystem>
#include <memory>

#include "commands.hpp"
#include "stillpoint/common/timing.hpp"
#include "stillpoint/loop/vocab_trainer.hpp"

namespace sp::app {

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
}

}  // namespace sp::app
