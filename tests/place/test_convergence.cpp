// Training that converges (issue 17): augmentation, the learning-rate schedule, validation with early
// stopping and the best epoch's weights, the training log and its curve.
#include <ATen/Parallel.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

#include "stillpoint/common/error.hpp"
#include "stillpoint/place/augment.hpp"
#include "stillpoint/place/model.hpp"
#include "stillpoint/place/schedule.hpp"
#include "stillpoint/place/trainer.hpp"
#include "stillpoint/place/training_log.hpp"
#include "tiny_places.hpp"

namespace sp::place {
namespace {

namespace fs = std::filesystem;

// A smooth colour image with structure (gradients and a disc): blur and crops change it visibly.
cv::Mat test_image(int h = 60, int w = 80) {
  cv::Mat im(h, w, CV_8UC3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      im.at<cv::Vec3b>(y, x) = cv::Vec3b(static_cast<uchar>(40 + 2 * x), static_cast<uchar>(60 + 2 * y),
                                         static_cast<uchar>((x * y) % 200 + 30));
  cv::circle(im, {w / 2, h / 2}, h / 4, cv::Scalar(220, 30, 90), cv::FILLED);
  return im;
}

double mean_abs_diff(const cv::Mat& a, const cv::Mat& b) {
  cv::Mat d;
  cv::absdiff(a, b, d);
  const auto m = cv::mean(d);
  return (m[0] + m[1] + m[2]) / 3;
}

TEST(PlaceAugment, SameKeySameOutputOtherKeyOtherOutput) {
  const cv::Mat im = test_image();
  const AugmentOptions o;
  const AugmentKey k{3, 2, 17, 1};
  const cv::Mat a = augment_image(im, o, k), b = augment_image(im, o, k);
  EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0);
  // Each part of the key changes the draw.
  for (const AugmentKey other :
       {AugmentKey{4, 2, 17, 1}, AugmentKey{3, 3, 17, 1}, AugmentKey{3, 2, 18, 1}, AugmentKey{3, 2, 17, 2}}) {
    EXPECT_GT(mean_abs_diff(a, augment_image(im, o, other)), 0.5)
        << other.seed << " " << other.epoch << " " << other.query << " " << other.slot;
  }
}

TEST(PlaceAugment, OffIsTheIdentity) {
  const cv::Mat im = test_image();
  AugmentOptions o;
  o.enabled = false;
  const cv::Mat out = augment_image(im, o, {1, 1, 1, 0});
  EXPECT_EQ(cv::norm(im, out, cv::NORM_INF), 0.0);
  EXPECT_NE(out.data, im.data);  // a copy: the caller may write into it
}

TEST(PlaceAugment, OnKeepsShapeAndRangeAndChangesTheImage) {
  const cv::Mat im = test_image();
  const AugmentOptions o;
  double biggest = 0;
  for (int q = 0; q < 40; ++q) {
    const cv::Mat out = augment_image(im, o, {1, 1, q, 0});
    ASSERT_EQ(out.size(), im.size());
    ASSERT_EQ(out.type(), im.type());
    const double d = mean_abs_diff(im, out);
    EXPECT_GT(d, 0.1) << q;
    // Still the same picture: the default ranges never wash it out (mean grey within a wide band).
    const auto m = cv::mean(out);
    EXPECT_GT((m[0] + m[1] + m[2]) / 3, 20.0) << q;
    EXPECT_LT((m[0] + m[1] + m[2]) / 3, 235.0) << q;
    biggest = std::max(biggest, d);
  }
  EXPECT_GT(biggest, 5.0);  // the photometric ranges do something
}

TEST(PlaceAugment, CropAloneZoomsALittleAndKeepsTheShape) {
  const cv::Mat im = test_image(120, 160);
  AugmentOptions o;
  o.brightness = o.contrast = o.saturation = o.gamma = 0;
  o.blur_probability = 0;
  o.noise_sigma_max = 0;
  int cropped = 0;
  for (int q = 0; q < 20; ++q) {
    const cv::Mat out = augment_image(im, o, {5, 1, q, 3});
    ASSERT_EQ(out.size(), im.size());
    const double d = mean_abs_diff(im, out);
    cropped += d > 0 ? 1 : 0;
    EXPECT_LT(d, 40.0) << q;  // ≤ 10 % per side: the same place
  }
  EXPECT_GT(cropped, 15);
  o.crop_max = 0;  // nothing left to change
  EXPECT_EQ(cv::norm(im, augment_image(im, o, {5, 1, 0, 3}), cv::NORM_INF), 0.0);
}

TEST(PlaceAugment, RejectsBadRangesAndImages) {
  AugmentOptions o;
  o.crop_max = 0.5;
  EXPECT_THROW(validate(o), sp::Error);
  o = {};
  o.blur_probability = 1.5;
  EXPECT_THROW(validate(o), sp::Error);
  EXPECT_NO_THROW(validate(AugmentOptions{}));
  EXPECT_THROW((void)augment_image(cv::Mat(4, 4, CV_8UC1), {}, {}), sp::Error);
}

TEST(PlaceSchedule, WarmupThenCosineAtKnownPoints) {
  LrSchedule s;  // cosine, 1 warm-up epoch, final factor 0.01
  const int spe = 10, epochs = 5;
  // Warm-up: (k + 1) / 10 of the base over the first epoch.
  EXPECT_DOUBLE_EQ(learning_rate(s, 1.0, 0, spe, epochs), 0.1);
  EXPECT_DOUBLE_EQ(learning_rate(s, 1.0, 4, spe, epochs), 0.5);
  EXPECT_DOUBLE_EQ(learning_rate(s, 1.0, 9, spe, epochs), 1.0);
  // Cosine over the remaining 40 steps: base at its start, the midpoint at step 30, → 1 % at the end.
  EXPECT_DOUBLE_EQ(learning_rate(s, 2.0, 10, spe, epochs), 2.0);
  EXPECT_NEAR(learning_rate(s, 2.0, 30, spe, epochs), 2.0 * (0.01 + 0.99 * 0.5), 1e-12);
  const double last = learning_rate(s, 2.0, 49, spe, epochs);
  EXPECT_NEAR(last, 2.0 * (0.01 + 0.99 * 0.5 * (1 + std::cos(M_PI * 39.0 / 40.0))), 1e-12);
  EXPECT_LT(last, 0.05);
  for (int k = 10; k < 49; ++k)
    EXPECT_GE(learning_rate(s, 1.0, k, spe, epochs), learning_rate(s, 1.0, k + 1, spe, epochs)) << k;
}

TEST(PlaceSchedule, ConstantAndStep) {
  LrSchedule c;
  c.kind = LrScheduleKind::Constant;
  c.warmup_epochs = 0;
  for (int k : {0, 7, 99}) EXPECT_DOUBLE_EQ(learning_rate(c, 0.3, k, 10, 10), 0.3);
  LrSchedule st;
  st.kind = LrScheduleKind::Step;
  st.warmup_epochs = 0;  // 9 epochs: decays every 3 (a third), ×0.1
  EXPECT_DOUBLE_EQ(learning_rate(st, 1.0, 0, 4, 9), 1.0);
  EXPECT_DOUBLE_EQ(learning_rate(st, 1.0, 11, 4, 9), 1.0);  // epoch 3, last step
  EXPECT_NEAR(learning_rate(st, 1.0, 12, 4, 9), 0.1, 1e-15);
  EXPECT_NEAR(learning_rate(st, 1.0, 35, 4, 9), 0.01, 1e-15);
  st.step_epochs = 2;
  st.step_gamma = 0.5;
  EXPECT_DOUBLE_EQ(learning_rate(st, 1.0, 7, 4, 9), 1.0);    // 0-based epoch 1
  EXPECT_DOUBLE_EQ(learning_rate(st, 1.0, 8, 4, 9), 0.5);    // epoch 2: first halving
  EXPECT_DOUBLE_EQ(learning_rate(st, 1.0, 16, 4, 9), 0.25);  // epoch 4: second
  // With a warm-up the decays count from its end.
  st.warmup_epochs = 1;
  EXPECT_DOUBLE_EQ(learning_rate(st, 1.0, 11, 4, 9), 1.0);  // 0-based epoch 2 = 1st after warm-up
  EXPECT_DOUBLE_EQ(learning_rate(st, 1.0, 12, 4, 9), 0.5);
}

TEST(PlaceSchedule, FractionalWarmupNeverExceedsTheBaseRate) {
  // Warm-ups that are not a whole number of steps: 0.5 epochs × 3 steps = 1.5 steps (uncapped, step 1
  // would be 2/1.5 = 1.33× base), 0.1 × 2 = 0.2 steps (uncapped: 5× base), 1.25 × 3 = 3.75 steps.
  struct Case {
    double warmup;
    std::int64_t spe;
  };
  for (const auto kind : {LrScheduleKind::Constant, LrScheduleKind::Cosine, LrScheduleKind::Step}) {
    for (const Case c : {Case{0.5, 3}, Case{0.1, 2}, Case{1.25, 3}, Case{0.7, 10}}) {
      LrSchedule s;
      s.kind = kind;
      s.warmup_epochs = c.warmup;
      const double base = 0.3;
      const int epochs = 6;
      double previous = 0;
      for (std::int64_t k = 0; k < c.spe * epochs; ++k) {
        const double lr = learning_rate(s, base, k, c.spe, epochs);
        EXPECT_LE(lr, base) << to_string(kind) << " warm-up " << c.warmup << " × " << c.spe << " step " << k;
        EXPECT_GT(lr, 0.0);
        // Within the warm-up the ramp rises (or reaches the base rate).
        if (static_cast<double>(k) < c.warmup * static_cast<double>(c.spe)) {
          EXPECT_GE(lr, previous) << k;
        }
        previous = lr;
      }
    }
  }
  LrSchedule s;
  s.kind = LrScheduleKind::Constant;
  s.warmup_epochs = 0.5;
  EXPECT_DOUBLE_EQ(learning_rate(s, 1.0, 0, 3, 4), 1.0 / 1.5);
  EXPECT_DOUBLE_EQ(learning_rate(s, 1.0, 1, 3, 4), 1.0);  // the last, partial warm-up step: capped
  EXPECT_DOUBLE_EQ(learning_rate(s, 1.0, 2, 3, 4), 1.0);
  s.warmup_epochs = 0.1;
  EXPECT_DOUBLE_EQ(learning_rate(s, 1.0, 0, 2, 4), 1.0);  // was 5× base
}

TEST(PlaceSchedule, ParseValidateAndEarlyStopping) {
  EXPECT_EQ(parse_lr_schedule("step"), LrScheduleKind::Step);
  EXPECT_THROW(parse_lr_schedule("linear"), sp::Error);
  LrSchedule s;
  s.warmup_epochs = -1;
  EXPECT_THROW(validate(s), sp::Error);
  s = {};
  s.step_gamma = 0;
  EXPECT_THROW(validate(s), sp::Error);

  EarlyStopping e(2);
  EXPECT_TRUE(e.update(1, 0.5));
  EXPECT_FALSE(e.update(2, 0.5));  // equal is not better
  EXPECT_FALSE(e.stop(2));
  EXPECT_FALSE(e.update(3, 0.4));
  EXPECT_TRUE(e.stop(3));
  EXPECT_EQ(e.best_epoch(), 1);
  EXPECT_TRUE(e.update(4, 0.6));
  EXPECT_FALSE(e.stop(4));
  EarlyStopping never(0);
  never.update(1, 0.9);
  for (int ep = 2; ep < 50; ++ep) never.update(ep, 0.1);
  EXPECT_FALSE(never.stop(49));
}

// Two training rooms and two held-back rooms, written once under the test scratch folder.
fs::path data_root() {
  return test::write_tiny_places(fs::path(SP_TEST_TMP_DIR) / "place_conv" / "train", {"a", "b"});
}
fs::path val_root() {
  return test::write_tiny_places(fs::path(SP_TEST_TMP_DIR) / "place_conv" / "val", {"c", "d"});
}

TrainOptions micro_options(const fs::path& out) {
  TrainOptions o;
  o.data = {data_root()};
  o.out = out;
  o.model = ModelConfig::scaled(ModelConfig::small(), 1.0 / 3.0, 1.0);  // widths 8-16-32-64
  o.model.clusters = 8;
  o.model.input_height = 48;
  o.model.input_width = 64;
  o.epochs = 3;
  o.optimizer = "sgd";
  o.lr = 0.05;
  o.negatives = 2;
  o.negative_pool = 8;
  o.queries_per_epoch = 8;
  o.batch = 4;
  o.refresh_every = 8;
  o.kmeans_images = 12;
  o.seed = 5;
  o.threads = 1;
  o.progress = false;
  return o;
}

// Largest |a − b| over all parameters of two model files (0: the same weights).
double max_weight_diff(const fs::path& a, const fs::path& b) {
  auto ma = load_model(a), mb = load_model(b);
  auto pa = ma->named_parameters();
  double d = 0;
  for (const auto& item : mb->named_parameters())
    d = std::max(d, (pa[item.key()] - item.value()).abs().max().item<double>());
  return d;
}

TEST(PlaceConvergence, EarlyStopsWhenValRecallCannotImprove) {
  const fs::path dir = fs::path(SP_TEST_TMP_DIR) / "place_conv";
  TrainOptions o = micro_options(dir / "frozen.pt");
  o.lr = 0;  // the weights never change, so neither does the val recall
  o.epochs = 20;
  o.patience = 2;
  o.val = {val_root()};
  const auto stats = train_model(o);
  // Epoch 1 sets the best; epochs 2 and 3 do not beat it: stop after epoch 3 (= 1 + patience).
  ASSERT_EQ(stats.size(), 3u);
  for (const auto& s : stats) {
    ASSERT_TRUE(s.val.has_value()) << s.epoch;
    EXPECT_EQ(s.val->recall[0], stats.front().val->recall[0]) << s.epoch;
    EXPECT_GT(s.val->queries, 0);
    EXPECT_EQ(s.lr, 0.0);
  }
  const auto log = nlohmann::json::parse(std::ifstream(o.out.string() + ".log.json"));
  EXPECT_EQ(log.size(), 3u);
  std::ifstream st(o.out.string() + ".ckpt.epoch");
  int last = 0, best = 0;
  st >> last >> best;
  EXPECT_EQ(last, 3);
  EXPECT_EQ(best, 1);
}

TEST(PlaceConvergence, WritesTheBestEpochsWeightsAndTheLog) {
  const fs::path dir = fs::path(SP_TEST_TMP_DIR) / "place_conv";
  TrainOptions o = micro_options(dir / "best.pt");
  o.epochs = 6;
  o.lr = 0.1;  // large enough that the val recall moves from epoch to epoch
  o.lr_schedule.kind = LrScheduleKind::Constant;  // a shorter rerun then follows the same rates
  o.lr_schedule.warmup_epochs = 0;
  o.val = {val_root() / "room_c", val_root() / "room_d"};
  const auto stats = train_model(o);
  ASSERT_EQ(stats.size(), 6u);
  int best = 0;
  double best_r1 = -1;
  for (const auto& s : stats) {
    ASSERT_TRUE(s.val.has_value());
    if (s.val->recall[0] > best_r1) best_r1 = s.val->recall[0], best = s.epoch;
  }
  std::printf("val R@1 per epoch:");
  for (const auto& s : stats) std::printf(" %.3f", s.val->recall[0]);
  std::printf("; best epoch %d\n", best);
  // The same run stopped after the best epoch (no validation: it does not touch the training) ends
  // with exactly the weights that --out must hold.
  TrainOptions again = micro_options(dir / "best_rerun.pt");
  again.epochs = best;
  again.lr = o.lr;
  again.lr_schedule = o.lr_schedule;
  train_model(again);
  EXPECT_EQ(max_weight_diff(o.out, again.out), 0.0) << "--out is not epoch " << best << "'s weights";
  if (best < o.epochs) {
    EXPECT_GT(max_weight_diff(o.out, o.out.string() + ".ckpt"), 0.0) << "the last epoch was kept";
  }

  // The log: one row per epoch in JSON and CSV, and a readable curve.
  const auto log = nlohmann::json::parse(std::ifstream(o.out.string() + ".log.json"));
  ASSERT_EQ(log.size(), 6u);
  for (size_t i = 0; i < log.size(); ++i) {
    EXPECT_EQ(log[i]["epoch"].get<int>(), static_cast<int>(i) + 1);
    EXPECT_DOUBLE_EQ(log[i]["loss"].get<double>(), stats[i].loss);
    EXPECT_DOUBLE_EQ(log[i]["lr"].get<double>(), 0.1);
    EXPECT_DOUBLE_EQ(log[i]["val_r1"].get<double>(), stats[i].val->recall[0]);
    EXPECT_TRUE(log[i]["val_r10"].is_number());
    EXPECT_TRUE(log[i].contains("seconds") && log[i].contains("active") && log[i].contains("val_r5"));
  }
  std::ifstream csv(o.out.string() + ".log.csv");
  std::string line;
  int lines = 0;
  while (std::getline(csv, line)) ++lines;
  EXPECT_EQ(lines, 7);
  const cv::Mat curve = cv::imread(o.out.string() + ".curve.png");
  ASSERT_FALSE(curve.empty());
  EXPECT_EQ(curve.cols, 800);
  EXPECT_EQ(curve.rows, 480);
}

TEST(PlaceConvergence, LogWithoutValidationHasNullRecall) {
  const fs::path dir = fs::path(SP_TEST_TMP_DIR) / "place_conv";
  TrainOptions o = micro_options(dir / "noval.pt");
  o.epochs = 2;
  const auto stats = train_model(o);
  ASSERT_EQ(stats.size(), 2u);
  EXPECT_FALSE(stats[0].val.has_value());
  const auto log = nlohmann::json::parse(std::ifstream(o.out.string() + ".log.json"));
  ASSERT_EQ(log.size(), 2u);
  EXPECT_TRUE(log[1]["val_r1"].is_null());
  EXPECT_GT(log[1]["lr"].get<double>(), 0.0);
  EXPECT_FALSE(cv::imread(o.out.string() + ".curve.png").empty());
  // Without --val the model is the last epoch's: the checkpoint after it.
  EXPECT_EQ(max_weight_diff(o.out, o.out.string() + ".ckpt"), 0.0);
}

TEST(PlaceConvergence, ResumeContinuesTheScheduleAndTheLog) {
  const fs::path dir = fs::path(SP_TEST_TMP_DIR) / "place_conv";
  TrainOptions straight = micro_options(dir / "straight.pt");  // cosine, 1 warm-up epoch
  straight.epochs = 3;
  const auto s3 = train_model(straight);
  TrainOptions first = micro_options(dir / "resumed.pt");
  first.epochs = 1;
  train_model(first);
  TrainOptions rest = micro_options(dir / "resumed.pt");
  rest.epochs = 3;
  rest.resume = dir / "resumed.pt.ckpt";
  const auto r = train_model(rest);
  ASSERT_EQ(s3.size(), 3u);
  ASSERT_EQ(r.size(), 2u);  // epochs 2 and 3
  // The rate is a function of the global step: the resumed epochs use the uninterrupted run's rates.
  EXPECT_EQ(r[0].epoch, 2);
  EXPECT_DOUBLE_EQ(r[0].lr, s3[1].lr);
  EXPECT_DOUBLE_EQ(r[1].lr, s3[2].lr);
  EXPECT_LT(s3[2].lr, s3[1].lr);  // the cosine is decaying
  // The log keeps epoch 1 from the first run.
  const auto log = nlohmann::json::parse(std::ifstream(rest.out.string() + ".log.json"));
  ASSERT_EQ(log.size(), 3u);
  EXPECT_EQ(log[0]["epoch"].get<int>(), 1);
  EXPECT_EQ(log[2]["epoch"].get<int>(), 3);
}

TEST(PlaceConvergence, ResumeIntoAnotherOutKeepsTheBestAndTheLog) {
  // A (2 epochs) → --resume A.ckpt --out B (epoch 3) → --resume B.ckpt --out C (epoch 4). lr 0: the
  // val recall never improves after epoch 1, so B and C never write a .best of their own and must
  // carry A's; their logs must keep the earlier runs' rows.
  const fs::path dir = fs::path(SP_TEST_TMP_DIR) / "place_conv" / "chain";
  fs::remove_all(dir);
  const auto options = [&](const std::string& name, int epochs) {
    TrainOptions o = micro_options(dir / name);
    o.lr = 0;
    o.epochs = epochs;
    o.val = {val_root()};
    return o;
  };
  train_model(options("a.pt", 2));
  TrainOptions b = options("b.pt", 3);
  b.resume = dir / "a.pt.ckpt";
  ASSERT_EQ(train_model(b).size(), 1u);
  ASSERT_TRUE(fs::exists(dir / "b.pt.ckpt.best")) << "B.ckpt.epoch names a best epoch B has no weights of";
  TrainOptions c = options("c.pt", 4);
  c.resume = dir / "b.pt.ckpt";
  ASSERT_EQ(train_model(c).size(), 1u);  // used to throw: b.pt.ckpt.best missing
  std::ifstream st(dir / "c.pt.ckpt.epoch");
  int last = 0, best = 0;
  st >> last >> best;
  EXPECT_EQ(last, 4);
  EXPECT_EQ(best, 1);
  EXPECT_EQ(max_weight_diff(dir / "c.pt", dir / "a.pt.ckpt.best"), 0.0);
  for (const char* name : {"b.pt", "c.pt"}) {
    const auto log = read_training_log(dir / name);
    ASSERT_EQ(log.size(), std::string(name) == "b.pt" ? 3u : 4u) << name;
    for (size_t i = 0; i < log.size(); ++i) EXPECT_EQ(log[i].epoch, static_cast<int>(i) + 1) << name;
  }
  // The checkpoint files were renamed into place: no .tmp left behind.
  for (const auto& e : fs::directory_iterator(dir)) EXPECT_NE(e.path().extension(), ".tmp") << e.path();
}

TEST(PlaceTrainingLog, NanLossReadsBackAsNaN) {
  const fs::path out = fs::path(SP_TEST_TMP_DIR) / "place_conv" / "nan_log" / "m.pt";
  fs::remove_all(out.parent_path());
  std::vector<EpochStats> rows(2);
  rows[0].epoch = 1;
  rows[0].loss = 0.25;
  rows[0].lr = 1e-3;
  rows[1].epoch = 2;
  rows[1].loss = std::numeric_limits<double>::quiet_NaN();  // a diverged epoch
  rows[1].lr = 1e-3;
  RecallResult v;
  v.recall = {0.5, 0.75, 1.0, 1.0};
  rows[1].val = v;
  write_training_log(out, rows);
  // JSON has no NaN: nlohmann writes null, which used to make the log (and so --resume) unreadable.
  const auto j = nlohmann::json::parse(std::ifstream(out.string() + ".log.json"));
  ASSERT_TRUE(j[1]["loss"].is_null());
  const auto back = read_training_log(out);
  ASSERT_EQ(back.size(), 2u);
  EXPECT_DOUBLE_EQ(back[0].loss, 0.25);
  EXPECT_TRUE(std::isnan(back[1].loss));
  EXPECT_DOUBLE_EQ(back[1].lr, 1e-3);
  ASSERT_TRUE(back[1].val.has_value());
  EXPECT_DOUBLE_EQ(back[1].val->recall[1], 0.75);
  EXPECT_FALSE(back[0].val.has_value());
  EXPECT_FALSE(fs::exists(out.string() + ".log.json.tmp"));
}

TEST(PlaceConvergence, RefusesValRoomsThatAreTrainedOn) {
  const fs::path dir = fs::path(SP_TEST_TMP_DIR) / "place_conv";
  TrainOptions o = micro_options(dir / "overlap.pt");
  o.val = {data_root() / "room_a"};
  try {
    train_model(o);
    ADD_FAILURE() << "trained with a val folder from --data";
  } catch (const sp::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("also in --data"), std::string::npos) << e.what();
  }
  // A copy of a training room elsewhere is still that room (scene.txt).
  const fs::path copy = dir / "copy_of_a";
  fs::remove_all(copy);
  fs::copy(data_root() / "room_a", copy, fs::copy_options::recursive);
  o.val = {copy};
  try {
    train_model(o);
    ADD_FAILURE() << "trained with a copy of a training room as val";
  } catch (const sp::InputError& e) {
    EXPECT_NE(std::string(e.what()).find("also a training room"), std::string::npos) << e.what();
  }
  o.val = {};
  o.patience = 3;
  EXPECT_THROW(train_model(o), sp::Error);  // patience without --val
}

}  // namespace
}  // namespace sp::place
