// Evaluation protocol, data-set readers and the BoW baseline.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "../support/shared_data.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/place/bow.hpp"
#include "stillpoint/place/retrieval.hpp"

namespace sp::place {
namespace {

namespace fs = std::filesystem;

TEST(PlaceRetrieval, RecallOnCraftedDistanceMatrix) {
  // 4 queries × 25 database images; distance = column index except where set below.
  Eigen::MatrixXf d(4, 25);
  for (int q = 0; q < 4; ++q)
    for (int j = 0; j < 25; ++j) d(q, j) = static_cast<float>(j);
  // q0: correct = {0} → rank 1. q1: correct = {3} → rank 4. q2: correct = {7, 12} → rank 8.
  // q3: correct = {22} → rank 23 (missed even at 20). Make q3's true match rank 1 in a copy below.
  const std::vector<std::vector<int>> gt = {{0}, {3}, {7, 12}, {22}};
  auto r = recall_at_n(d, gt);
  EXPECT_EQ(r.queries, 4);
  EXPECT_DOUBLE_EQ(r.recall[0], 0.25);  // @1
  EXPECT_DOUBLE_EQ(r.recall[1], 0.50);  // @5
  EXPECT_DOUBLE_EQ(r.recall[2], 0.75);  // @10
  EXPECT_DOUBLE_EQ(r.recall[3], 0.75);  // @20
  d(3, 22) = -1.0f;
  r = recall_at_n(d, gt);
  EXPECT_DOUBLE_EQ(r.recall[0], 0.50);
  EXPECT_DOUBLE_EQ(r.recall[3], 1.00);
  EXPECT_THROW(recall_at_n(d, {{0}}), sp::Error);
}

TEST(PlaceRetrieval, TopNAndSquaredDistances) {
  Eigen::MatrixXf q(1, 2), db(3, 2);
  q << 0, 0;
  db << 3, 0, 1, 0, 0, 2;
  const auto d = squared_distances(q, db);
  EXPECT_FLOAT_EQ(d(0, 0), 9.0f);
  EXPECT_FLOAT_EQ(d(0, 1), 1.0f);
  EXPECT_FLOAT_EQ(d(0, 2), 4.0f);
  EXPECT_EQ(top_n(d, 20)[0], (std::vector<int>{1, 2, 0}));
}

TEST(PlaceRetrieval, PositiveAndNegativeRules) {
  PlaceImage a, b;
  a.room = b.room = "r";
  b.t = Eigen::Vector3d(0.4, 0, 0);
  b.q = Eigen::Quaterniond(Eigen::AngleAxisd(25.0 * M_PI / 180, Eigen::Vector3d::UnitY()));
  const PlaceRules rules;
  EXPECT_TRUE(is_positive(a, b, rules));
  EXPECT_NEAR(rotation_angle_deg(a.q, b.q), 25.0, 1e-9);
  b.q = Eigen::Quaterniond(Eigen::AngleAxisd(35.0 * M_PI / 180, Eigen::Vector3d::UnitY()));
  EXPECT_FALSE(is_positive(a, b, rules));
  EXPECT_FALSE(is_negative(a, b, rules));
  b.t = Eigen::Vector3d(3.5, 0, 0);
  EXPECT_TRUE(is_negative(a, b, rules));
  PlaceRules view_aware;
  view_aware.negative_min_angle_deg = 60;
  EXPECT_FALSE(is_negative(a, b, view_aware)) << "3.5 m back, 35 deg apart: may see the same wall";
  b.q = Eigen::Quaterniond(Eigen::AngleAxisd(90.0 * M_PI / 180, Eigen::Vector3d::UnitY()));
  EXPECT_TRUE(is_negative(a, b, view_aware));
  b.t = Eigen::Vector3d(2.0, 0, 0);
  EXPECT_FALSE(is_negative(a, b, view_aware)) << "within the negative distance";
  b.t.setZero();
  b.room = "other";
  EXPECT_TRUE(is_negative(a, b, rules));
  EXPECT_TRUE(is_negative(a, b, view_aware));
  EXPECT_FALSE(is_positive(a, b, rules));
}

TEST(PlaceRetrieval, PlacesFolderSplitAndErrors) {
  const fs::path dir = fs::path(SP_TEST_TMP_DIR) / "place" / "room_a";
  fs::create_directories(dir);
  {
    std::ofstream(dir / "scene.txt") << "random_42\n";
    std::ofstream p(dir / "poses.txt");
    p << "rgb/000000.jpg 0 0 0 0 0 0 1\n"    // db 0
      << "rgb/000001.jpg 0.1 0 0 0 0 0 1\n"  // query: matches db 0
      << "rgb/000002.jpg 5 0 0 0 0 0 1\n"    // db 1
      << "rgb/000003.jpg 9 9 0 0 0 0 1\n";   // query without a match: dropped
  }
  const auto imgs = load_places_folder(dir);
  ASSERT_EQ(imgs.size(), 4u);
  EXPECT_EQ(imgs[1].room, "random_42");
  const auto set = load_retrieval_set(dir);
  EXPECT_EQ(set.name, "places");
  ASSERT_EQ(set.queries.size(), 1u);
  EXPECT_EQ(set.database.size(), 2u);
  EXPECT_EQ(set.ground_truth[0], (std::vector<int>{0}));
  EXPECT_EQ(set.dropped_queries, 1);
  std::ofstream(dir / "poses.txt", std::ios::app) << "rgb/000004.jpg 1 2\n";
  try {
    load_places_folder(dir);
    FAIL() << "expected InputError";
  } catch (const sp::InputError& e) {
    EXPECT_EQ(e.line(), 5);
  }
}

TEST(PlaceRetrieval, RealSetsFollowTheirProtocols) {
  const fs::path vpr = fs::path(SP_SHARED_DIR) / "data" / "vpr";
  SP_REQUIRE_SHARED(vpr / "nordland", vpr / "corridor");
  const auto nord = load_retrieval_set(vpr / "nordland");
  EXPECT_EQ(nord.queries.size(), nord.database.size());
  EXPECT_EQ(nord.ground_truth[10], (std::vector<int>{8, 9, 10, 11, 12}));
  EXPECT_EQ(nord.ground_truth[0], (std::vector<int>{0, 1, 2}));
  EXPECT_NE(nord.queries[0].string().find("winter"), std::string::npos);
  const auto cor = load_retrieval_set(vpr / "corridor");
  EXPECT_EQ(cor.queries.size(), 111u);
  EXPECT_EQ(cor.ground_truth[1], (std::vector<int>{0, 1, 2, 3}));
}

TEST(PlaceRetrieval, BowPrefersTheSameSceneAndRoundTrips) {
  // Two textured synthetic scenes; a shifted copy of scene A must score higher with A than with B.
  auto scene = [](int seed) {
    cv::Mat im(240, 320, CV_8UC3, cv::Scalar(128, 128, 128));
    cv::RNG rng(static_cast<uint64_t>(seed));
    for (int i = 0; i < 60; ++i) {
      cv::rectangle(
          im, cv::Rect(rng.uniform(0, 300), rng.uniform(0, 220), rng.uniform(8, 40), rng.uniform(8, 40)),
          cv::Scalar(rng.uniform(0, 255), rng.uniform(0, 255), rng.uniform(0, 255)), cv::FILLED);
    }
    return im;
  };
  const cv::Mat a = scene(1), b = scene(2);
  cv::Mat a2;
  const cv::Mat shift = (cv::Mat_<double>(2, 3) << 1, 0, 6, 0, 1, 4);
  cv::warpAffine(a, a2, shift, a.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  const auto da = orb_descriptors(a), db = orb_descriptors(b), da2 = orb_descriptors(a2);
  ASSERT_GT(da.rows, 50);
  const auto voc = BowVocabulary::train({da, db, orb_descriptors(scene(3))}, 64, 5, 1);
  const float same = BowVocabulary::score(voc.transform(da), voc.transform(da2));
  const float other = BowVocabulary::score(voc.transform(db), voc.transform(da2));
  EXPECT_GT(same, other);
  EXPECT_NEAR(BowVocabulary::score(voc.transform(da), voc.transform(da)), 1.0f, 1e-5f);
  EXPECT_EQ(BowVocabulary::score(voc.transform(da), voc.transform(cv::Mat())), 0.0f);
  const fs::path file = fs::path(SP_TEST_TMP_DIR) / "place" / "voc.bin";
  fs::create_directories(file.parent_path());
  voc.save(file);
  const auto back = BowVocabulary::load(file);
  EXPECT_EQ(back.size(), 64);
  EXPECT_TRUE(back.transform(da2).isApprox(voc.transform(da2)));
}

}  // namespace
}  // namespace sp::place
