#include "stillpoint/loop/vocab_trainer.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <opencv2/imgcodecs.hpp>

#include "stillpoint/common/error.hpp"
#include "stillpoint/common/progress_bar.hpp"
#include "stillpoint/common/timing.hpp"
#include "stillpoint/features/orb_extractor.hpp"

namespace sp::loop {
namespace {

bool is_image(const std::filesystem::path& p) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return ext == ".png" || ext == ".jpg" || ext == ".jpeg";
}

}  // namespace

std::vector<std::filesystem::path> collect_training_images(const std::vector<std::filesystem::path>& inputs,
                                                           std::size_t max_images) {
  std::vector<std::filesystem::path> all;
  for (const auto& input : inputs) {
    if (!std::filesystem::is_directory(input)) throw sp::InputError(input.string(), 0, "not a folder");
    const auto dir = std::filesystem::is_directory(input / "rgb") ? input / "rgb" : input;
    std::vector<std::filesystem::path> here;
    for (const auto& e : std::filesystem::directory_iterator(dir)) {
      if (e.is_regular_file() && is_image(e.path())) here.push_back(e.path());
    }
    if (here.empty()) throw sp::InputError(dir.string(), 0, "no .png/.jpg images in this folder");
    std::sort(here.begin(), here.end());
    all.insert(all.end(), here.begin(), here.end());
  }
  if (max_images == 0 || all.size() <= max_images) return all;
  std::vector<std::filesystem::path> thinned;
  thinned.reserve(max_images);
  for (std::size_t i = 0; i < max_images; ++i) thinned.push_back(all[i * all.size() / max_images]);
  return thinned;
}

std::vector<cv::Mat> extract_training_descriptors(const std::vector<std::filesystem::path>& images,
                                                  int features) {
  if (features < 100 || features > 10000) throw sp::Error("vocab training: features must be in [100, 10000]");
  sp::feat::OrbConfig cfg;
  cfg.n_features = features;
  sp::feat::OrbExtractor orb(cfg);
  std::vector<cv::Mat> out;
  out.reserve(images.size());
  sp::ProgressBar bar("ORB", images.size());
  for (std::size_t i = 0; i < images.size(); ++i) {
    const cv::Mat gray = cv::imread(images[i].string(), cv::IMREAD_GRAYSCALE);
    if (gray.empty()) throw sp::InputError(images[i].string(), 0, "cannot read the image");
    std::vector<cv::KeyPoint> kps;
    cv::Mat desc;
    orb.extract(gray, kps, desc);
    out.push_back(desc);
    bar.update(i + 1);
  }
  bar.finish();
  return out;
}

Vocabulary train_vocabulary(const VocabTrainingOptions& options, VocabTrainingReport* report) {
  options.vocabulary.validate();
  sp::Stopwatch sw;
  const auto images = collect_training_images(options.inputs, options.max_images);
  const auto descriptors = extract_training_descriptors(images, options.features);
  const double extract_s = sw.elapsed_ms() / 1000.0;
  std::size_t n = 0;
  for (const auto& d : descriptors) n += static_cast<std::size_t>(d.rows);
  spdlog::info("vocab: {} descriptors from {} images in {:.1f} s; training k={} L={}", n, images.size(),
               extract_s, options.vocabulary.k, options.vocabulary.levels);
  sw.restart();
  Vocabulary v = Vocabulary::train(descriptors, options.vocabulary, options.seed);
  if (report != nullptr) {
    report->images = images.size();
    report->descriptors = n;
    report->extract_s = extract_s;
    report->train_s = sw.elapsed_ms() / 1000.0;
  }
  return v;
}

}  // namespace sp::loop
