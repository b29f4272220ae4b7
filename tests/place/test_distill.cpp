// Feature distillation (vpr distill): the student learns the teacher's local features, the result is a
// usable ParC_NetVLAD model, and bad teachers or options fail with a clear error.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <string>

#include "stillpoint/common/error.hpp"
#include "stillpoint/place/descriptor.hpp"
#include "stillpoint/place/distill.hpp"
#include "stillpoint/place/trainer.hpp"
#include "tiny_places.hpp"

namespace sp::place {
namespace {

namespace fs = std::filesystem;

const fs::path kTeacher = fs::path(SP_SOURCE_DIR) / "models" / "yolox_nano" / "yolox_nano.onnx";

DistillOptions tiny_options(const std::string& name) {
  DistillOptions o;
  const fs::path root = fs::temp_directory_path() / ("sp_distill_" + std::to_string(getpid()));
  o.data = {test::write_tiny_places(root / "rooms", {"d1", "d2"}, 12)};
  o.out = root / (name + ".pt");
  o.teacher = kTeacher;
  o.model = ModelConfig::scaled(ModelConfig::small(), 0.5, 1.0);
  o.model.input_height = 64;
  o.model.input_width = 96;
  o.model.clusters = 8;
  o.steps = 60;
  o.batch = 6;
  o.lr = 3e-3;
  o.kmeans_images = 24;
  o.augment.enabled = false;
  o.threads = 1;
  o.progress = false;
  return o;
}

TEST(PlaceDistill, StudentLearnsTheTeachersFeatures) {
  const auto o = tiny_options("learns");
  const auto stats = distill_model(o);
  EXPECT_EQ(stats.steps, o.steps);
  // 1 − cosine per location, summed over the two levels: a random student is far from the teacher,
  // and fitting 24 images' teacher maps must take most of that distance away.
  EXPECT_GT(stats.first_loss, 0.5);
  EXPECT_LT(stats.last_loss, 0.7 * stats.first_loss) << stats.first_loss << " -> " << stats.last_loss;
  // The written file is a complete model: it loads and gives unit-length descriptors of K·D values.
  auto extractor = PlaceDescriptorExtractor::load(o.out);
  const Eigen::VectorXf d =
      extractor.describe(cv::imread((o.data[0] / "room_d1" / "rgb" / "000000.jpg").string()));
  ASSERT_EQ(static_cast<int>(d.size()), o.model.descriptor_dim());
  EXPECT_NEAR(d.norm(), 1.0, 1e-4);
}

TEST(PlaceDistill, SameSeedSameModelOtherSeedOtherModel) {
  auto o = tiny_options("seed_a");
  o.steps = 8;
  distill_model(o);
  const fs::path first = o.out;
  o.out = first.parent_path() / "seed_b.pt";
  distill_model(o);
  o.out = first.parent_path() / "seed_c.pt";
  o.seed = 2;
  distill_model(o);
  const cv::Mat im = cv::imread((o.data[0] / "room_d1" / "rgb" / "000005.jpg").string());
  auto a = PlaceDescriptorExtractor::load(first),
       b = PlaceDescriptorExtractor::load(first.parent_path() / "seed_b.pt"),
       c = PlaceDescriptorExtractor::load(o.out);
  const Eigen::VectorXf da = a.describe(im);
  EXPECT_EQ((da - b.describe(im)).norm(), 0.0f);
  EXPECT_GT((da - c.describe(im)).norm(), 1e-3f);
}

TEST(PlaceDistill, ALevelCanBeLeftOut) {
  auto o = tiny_options("mid_only");
  o.teacher_top = "";
  o.steps = 20;
  const auto stats = distill_model(o);
  // One level: a cosine distance, so at most 2; it must still fall.
  EXPECT_LT(stats.first_loss, 2.0);
  EXPECT_LT(stats.last_loss, stats.first_loss);
  EXPECT_TRUE(fs::exists(o.out));
}

TEST(PlaceDistill, TrainingStartsFromTheDistilledModel) {
  auto d = tiny_options("init");
  d.steps = 10;
  distill_model(d);
  TrainOptions t;
  t.data = d.data;
  t.out = d.out.parent_path() / "from_init.pt";
  t.init = d.out;
  t.epochs = 1;
  t.lr = 0;  // no step changes anything: the result must be the --init model itself
  t.queries_per_epoch = 4;
  t.negative_pool = 5;
  t.augment.enabled = false;
  t.threads = 1;
  t.progress = false;
  train_model(t);
  const cv::Mat im = cv::imread((d.data[0] / "room_d2" / "rgb" / "000003.jpg").string());
  auto a = PlaceDescriptorExtractor::load(d.out), b = PlaceDescriptorExtractor::load(t.out);
  EXPECT_LT((a.describe(im) - b.describe(im)).norm(), 1e-6);
  // A fresh model of the default architecture would not even have the same descriptor size.
  EXPECT_NE(ModelConfig::small().descriptor_dim(), d.model.descriptor_dim());

  t.resume = t.out.string() + ".ckpt";
  EXPECT_THROW(validate(t), sp::Error);  // --init and --resume exclude each other
}

TEST(PlaceDistill, RefusesAMissingTeacherOrLayerNamingTheFile) {
  auto o = tiny_options("bad");
  o.teacher = "/nonexistent/teacher.onnx";
  try {
    distill_model(o);
    FAIL() << "a missing teacher was accepted";
  } catch (const sp::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/teacher.onnx"), std::string::npos) << e.what();
  }
  o.teacher = kTeacher;
  o.teacher_mid = "no_such_layer";
  try {
    distill_model(o);
    FAIL() << "an unknown layer was accepted";
  } catch (const sp::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("no_such_layer"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(o.out));
}

TEST(PlaceDistill, ValidateRefusesOptionsOutOfRange) {
  const auto good = tiny_options("validate");
  EXPECT_NO_THROW(validate(good));
  auto o = good;
  o.teacher_mid = "";
  o.top_weight = 0;  // nothing left to learn
  EXPECT_THROW(validate(o), sp::Error);
  o = good;
  o.steps = 0;
  EXPECT_THROW(validate(o), sp::Error);
  o = good;
  o.lr = std::nan("");
  EXPECT_THROW(validate(o), sp::Error);
  o = good;
  o.teacher.clear();
  EXPECT_THROW(validate(o), sp::Error);
}

}  // namespace
}  // namespace sp::place
