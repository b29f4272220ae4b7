// Save/load of models, the descriptor API, and that the network can learn (overfits 8 triplets).
#include <ATen/Parallel.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "stillpoint/common/error.hpp"
#include "stillpoint/place/descriptor.hpp"
#include "stillpoint/place/model.hpp"
#include "stillpoint/place/trainer.hpp"

namespace sp::place {
namespace {

namespace fs = std::filesystem;

ModelConfig micro_config() {
  ModelConfig c = ModelConfig::scaled(ModelConfig::small(), 1.0 / 3.0, 1.0);  // widths 8-16-32-64
  c.clusters = 8;
  c.input_height = 48;
  c.input_width = 64;
  return c;
}

cv::Mat random_image(int seed, int h = 60, int w = 80) {
  cv::Mat im(h, w, CV_8UC3);
  cv::RNG rng(static_cast<uint64_t>(seed));
  rng.fill(im, cv::RNG::UNIFORM, 0, 256);
  return im;
}

TEST(PlaceTraining, SaveLoadRoundTripGivesIdenticalDescriptors) {
  at::set_num_threads(1);
  torch::manual_seed(5);
  const fs::path dir = fs::path(SP_TEST_TMP_DIR) / "place";
  fs::create_directories(dir);
  const fs::path file = dir / "roundtrip.pt";
  ParCNetVLAD net(micro_config());
  net->eval();
  save_model(net, file);
  const cv::Mat im = random_image(1);
  torch::Tensor direct;
  {
    torch::NoGradGuard g;
    direct = net(image_to_tensor(im, 48, 64)).squeeze(0);
  }
  auto ex = PlaceDescriptorExtractor::load(file, 1);
  EXPECT_EQ(ex.dimension(), 8 * 64);
  EXPECT_EQ(ex.input_width(), 64);
  const Eigen::VectorXf d = ex.describe(im);
  ASSERT_EQ(d.size(), direct.numel());
  for (Eigen::Index i = 0; i < d.size(); ++i) ASSERT_EQ(d[i], direct[i].item<float>()) << i;
  EXPECT_NEAR(d.norm(), 1.0f, 1e-5f);
  // Batch and single calls agree; a different image gives a different descriptor.
  const Eigen::MatrixXf b = ex.describe_batch({im, random_image(2)});
  EXPECT_LT((b.row(0).transpose() - d).norm(), 1e-5f);
  EXPECT_GT((b.row(1).transpose() - d).norm(), 1e-4f);
  // Grey images are accepted too.
  cv::Mat grey;
  cv::cvtColor(im, grey, cv::COLOR_BGR2GRAY);
  EXPECT_EQ(ex.describe(grey).size(), d.size());
}

TEST(PlaceTraining, LoadRejectsMissingAndForeignFiles) {
  const fs::path dir = fs::path(SP_TEST_TMP_DIR) / "place";
  fs::create_directories(dir);
  EXPECT_THROW(PlaceDescriptorExtractor::load(dir / "nope.pt"), sp::InputError);
  const fs::path junk = dir / "junk.pt";
  std::ofstream(junk) << "not a model";
  EXPECT_THROW(PlaceDescriptorExtractor::load(junk), sp::InputError);
}

TEST(PlaceTraining, TinyModelOverfitsEightTriplets) {
  at::set_num_threads(1);
  torch::manual_seed(7);
  ParCNetVLAD net(micro_config());
  // Queries, positives = queries + small noise, two negatives each: all random images.
  const auto q = torch::randn({8, 3, 48, 64});
  const auto p = q + 0.3 * torch::randn({8, 3, 48, 64});
  const auto n = torch::randn({16, 3, 48, 64});
  const auto batch = torch::cat({q, p, n});
  torch::optim::Adam opt(net->parameters(), torch::optim::AdamOptions(3e-3));
  auto loss_of = [&] {
    const auto d = net(batch);
    return triplet_loss(d.narrow(0, 0, 8), d.narrow(0, 8, 8), d.narrow(0, 16, 16).view({8, 2, -1}), 0.1);
  };
  net->train();
  double first = 0, last = 0;
  for (int step = 0; step < 150; ++step) {
    const auto loss = loss_of();
    if (step == 0) first = loss.item<double>();
    last = loss.item<double>();
    if (last < 1e-4) break;
    opt.zero_grad();
    loss.backward();
    opt.step();
  }
  EXPECT_GT(first, 0.05);
  EXPECT_LT(last, 0.01) << "first loss " << first;
}

}  // namespace
}  // namespace sp::place
