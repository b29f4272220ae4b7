// Shapes and operators of the ParC_NetVLAD network, each module alone.
#include <ATen/Parallel.h>
#include <gtest/gtest.h>

#include "stillpoint/place/model.hpp"

namespace sp::place {
namespace {

class PlaceModel : public ::testing::Test {
 protected:
  void SetUp() override {
    at::set_num_threads(1);
    torch::manual_seed(3);
  }
};

TEST_F(PlaceModel, SmallVariantStageShapes) {
  ModelConfig cfg = ModelConfig::small();
  EXPECT_EQ(cfg.depths, (std::array<int, 4>{1, 1, 3, 1}));
  EXPECT_EQ(cfg.widths, (std::array<int, 4>{24, 48, 96, 192}));
  Backbone net(cfg);
  torch::NoGradGuard g;
  const auto outs = net->stage_outputs(torch::randn({2, 3, 128, 160}));
  ASSERT_EQ(outs.size(), 5u);
  EXPECT_EQ(outs[0].sizes(), (std::vector<int64_t>{2, 24, 32, 40}));  // stem
  EXPECT_EQ(outs[1].sizes(), (std::vector<int64_t>{2, 24, 32, 40}));
  EXPECT_EQ(outs[2].sizes(), (std::vector<int64_t>{2, 48, 16, 20}));
  EXPECT_EQ(outs[3].sizes(), (std::vector<int64_t>{2, 96, 8, 10}));
  EXPECT_EQ(outs[4].sizes(), (std::vector<int64_t>{2, 192, 4, 5}));
}

TEST_F(PlaceModel, ParCBlocksWhereThePaperPutsThem) {
  ModelConfig cfg = ModelConfig::tiny();
  Backbone net(cfg);
  auto is_parc = [&](int stage, int block) {
    auto seq = net->stages[static_cast<size_t>(stage)]->as<torch::nn::Sequential>();
    return (*seq)[static_cast<size_t>(block)]->as<ConvNeXtBlockImpl>()->parc;
  };
  for (int b = 0; b < 6; ++b) EXPECT_FALSE(is_parc(2, b)) << b;
  for (int b = 6; b < 9; ++b) EXPECT_TRUE(is_parc(2, b)) << b;
  EXPECT_FALSE(is_parc(3, 1));
  EXPECT_TRUE(is_parc(3, 2));
  EXPECT_FALSE(is_parc(0, 2));
  cfg.parc = false;
  Backbone plain(cfg);
  auto seq = plain->stages[3]->as<torch::nn::Sequential>();
  EXPECT_FALSE((*seq)[2]->as<ConvNeXtBlockImpl>()->parc);
}

// The full ConvNeXt-Tiny at 480×640: the stem and downsampling layers alone give the stride and
// channel arithmetic (a full forward is too slow for CI); the head then maps 768×15×20 to 64·768.
TEST_F(PlaceModel, TinyShapesAt480x640) {
  const ModelConfig cfg = ModelConfig::tiny();
  EXPECT_EQ(cfg.descriptor_dim(), 64 * 768);
  Backbone net(cfg);
  torch::NoGradGuard g;
  auto x = torch::randn({1, 3, 480, 640});
  const std::vector<std::vector<int64_t>> expected = {
      {1, 96, 120, 160}, {1, 192, 60, 80}, {1, 384, 30, 40}, {1, 768, 15, 20}};
  for (size_t i = 0; i < 4; ++i) {
    x = net->downsample[i]->as<torch::nn::Sequential>()->forward(x);
    EXPECT_EQ(x.sizes(), expected[i]) << "after downsampling layer " << i;
  }
  // Last stage (one plain block, one plain, one ParC) runs on the real 15×20 map.
  x = net->stages[3]->as<torch::nn::Sequential>()->forward(x);
  EXPECT_EQ(x.sizes(), (std::vector<int64_t>{1, 768, 15, 20}));
  CBAM cbam(768);
  NetVLAD vlad(64, 768);
  const auto d = vlad(cbam(x));
  EXPECT_EQ(d.sizes(), (std::vector<int64_t>{1, 64 * 768}));
}

TEST_F(PlaceModel, ParCEqualsReferenceCircularConvolution) {
  for (bool vertical : {true, false}) {
    ParCOperator op(3, vertical, /*base_size=*/4);
    torch::NoGradGuard g;
    const auto x = torch::randn({2, 3, 5, 6});
    const auto y = op(x);
    ASSERT_EQ(y.sizes(), x.sizes());
    const int64_t L = vertical ? 5 : 6;
    const auto k = op->instance_kernel(L).reshape({3, L});  // bilinearly resized meta-kernel
    const auto pe = op->instance_pe(L).reshape({3, L});
    EXPECT_EQ(op->instance_kernel(4).reshape({3, 4}).equal(op->meta_kernel.reshape({3, 4})), true);
    auto xa = x.accessor<float, 4>();
    auto ka = k.accessor<float, 2>();
    auto pa = pe.accessor<float, 2>();
    auto ya = y.accessor<float, 4>();
    double max_err = 0;
    for (int n = 0; n < 2; ++n)
      for (int c = 0; c < 3; ++c)
        for (int i = 0; i < 5; ++i)
          for (int j = 0; j < 6; ++j) {
            double s = op->bias[c].item<float>();
            for (int t = 0; t < L; ++t) {
              const int ii = vertical ? (i + t) % 5 : i, jj = vertical ? j : (j + t) % 6;
              const int pos = vertical ? ii : jj;
              s += ka[c][t] * (xa[n][c][ii][jj] + pa[c][pos]);
            }
            max_err = std::max(max_err, std::abs(s - ya[n][c][i][j]));
          }
    EXPECT_LT(max_err, 1e-5) << (vertical ? "ParC-H" : "ParC-W");
  }
}

TEST_F(PlaceModel, ParCKernelFollowsFeatureSize) {
  ParCOperator op(2, false, 8);
  torch::NoGradGuard g;
  EXPECT_EQ(op->instance_kernel(20).sizes(), (std::vector<int64_t>{2, 1, 1, 20}));
  // align_corners interpolation keeps the end points of the meta-kernel.
  EXPECT_NEAR(op->instance_kernel(20)[1][0][0][19].item<float>(), op->meta_kernel[1][0][0][7].item<float>(),
              1e-6);
  EXPECT_EQ(op(torch::randn({1, 2, 3, 20})).sizes(), (std::vector<int64_t>{1, 2, 3, 20}));
}

TEST_F(PlaceModel, CBAMKeepsShapeAndWeightsInUnitInterval) {
  CBAM cbam(32);
  torch::NoGradGuard g;
  const auto x = torch::randn({2, 32, 6, 7}) * 5;
  const auto [y, ca, sa] = cbam->forward_with_weights(x);
  EXPECT_EQ(y.sizes(), x.sizes());
  EXPECT_EQ(ca.sizes(), (std::vector<int64_t>{2, 32, 1, 1}));
  EXPECT_EQ(sa.sizes(), (std::vector<int64_t>{2, 1, 6, 7}));
  EXPECT_GT(ca.min().item<float>(), 0.0f);
  EXPECT_LT(ca.max().item<float>(), 1.0f);
  EXPECT_GT(sa.min().item<float>(), 0.0f);
  EXPECT_LT(sa.max().item<float>(), 1.0f);
  EXPECT_TRUE(torch::allclose(y, x * ca * sa));
}

TEST_F(PlaceModel, NetVLADIsNormalisedPerBlockAndOverall) {
  NetVLAD vlad(8, 16);
  torch::NoGradGuard g;
  const auto d = vlad(torch::randn({3, 16, 4, 5}));
  ASSERT_EQ(d.sizes(), (std::vector<int64_t>{3, 8 * 16}));
  EXPECT_TRUE(torch::allclose(d.norm(2, 1), torch::ones({3}), 1e-5, 1e-5));
  // Intra-normalised: every K block has the same norm, 1/sqrt(K).
  const auto blocks = d.view({3, 8, 16}).norm(2, 2);
  EXPECT_TRUE(torch::allclose(blocks, torch::full({3, 8}, 1.0 / std::sqrt(8.0)), 1e-5, 1e-5));
}

TEST_F(PlaceModel, NetVLADMatchesExplicitAggregation) {
  NetVLAD vlad(3, 4);
  torch::NoGradGuard g;
  const auto x = torch::randn({1, 4, 2, 2});
  const auto d = vlad(x).view({3, 4});
  const auto xn = torch::nn::functional::normalize(x, torch::nn::functional::NormalizeFuncOptions().dim(1));
  const auto logits = vlad->assign(xn).view({3, 4});
  const auto a = torch::softmax(logits, 0);
  auto v = torch::zeros({3, 4});
  for (int k = 0; k < 3; ++k)
    for (int i = 0; i < 4; ++i) v[k] += a[k][i] * (xn.view({4, 4}).select(1, i) - vlad->centroids[k]);
  v = torch::nn::functional::normalize(v, torch::nn::functional::NormalizeFuncOptions().dim(1));
  v = v / std::sqrt(3.0);
  EXPECT_TRUE(torch::allclose(d, v, 1e-5, 1e-5));
}

TEST_F(PlaceModel, TripletLossOnCraftedTriplet) {
  const auto q = torch::tensor({0.0f, 0.0f}).view({1, 2});
  const auto p = torch::tensor({0.1f, 0.0f}).view({1, 2});                 // d² = 0.01
  const auto n = torch::tensor({0.2f, 0.0f, 0.0f, 1.0f}).view({1, 2, 2});  // d² = 0.04, 1.0
  // max(0, 0.01 + 0.1 − 0.04) + max(0, 0.01 + 0.1 − 1) = 0.07
  EXPECT_NEAR(triplet_loss(q, p, n, 0.1).item<float>(), 0.07f, 1e-6);
  EXPECT_NEAR(triplet_loss(q, p, n, 0.0).item<float>(), 0.0f, 1e-7);
}

TEST_F(PlaceModel, ForwardIsL2NormalisedAndConfigurable) {
  ModelConfig cfg = ModelConfig::scaled(ModelConfig::small(), 0.5, 1.0);
  cfg.clusters = 8;
  cfg.input_height = 64;
  cfg.input_width = 96;
  for (bool cbam : {false, true}) {
    cfg.cbam = cbam;
    ParCNetVLAD net(cfg);
    torch::NoGradGuard g;
    const auto d = net(torch::randn({2, 3, 64, 96}));
    EXPECT_EQ(d.size(1), cfg.descriptor_dim());
    EXPECT_TRUE(torch::allclose(d.norm(2, 1), torch::ones({2}), 1e-5, 1e-5));
  }
}

TEST_F(PlaceModel, ConfigFromYaml) {
  const auto r = sp::ConfigReader::from_string("variant: small\nparc: false\nclusters: 16\n", "test");
  const auto c = ModelConfig::from_yaml(r);
  r.finish();
  EXPECT_FALSE(c.parc);
  EXPECT_EQ(c.clusters, 16);
  EXPECT_THROW(ModelConfig::from_yaml(sp::ConfigReader::from_string("clusters: 1\n", "t")), sp::ConfigError);
}

}  // namespace
}  // namespace sp::place
