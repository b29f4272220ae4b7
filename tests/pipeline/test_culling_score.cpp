// Culling is scored per keypoint against a ground-truth mask (non-zero = dynamic); frames without a
// mask are skipped; the masks are read when the score is asked for, not while tracking.
#include <gtest/gtest.h>

#include <filesystem>
#include <opencv2/imgcodecs.hpp>

#include "stillpoint/pipeline/culling_score.hpp"

namespace sp::pipeline {
namespace {

namespace fs = std::filesystem;

TEST(CullingScore, CountsKeypointsAgainstTheMaskAndSkipsFramesWithoutOne) {
  const fs::path dir = fs::path(SP_TEST_TMP_DIR) / "culling_score";
  fs::remove_all(dir);
  fs::create_directories(dir / "masks");
  cv::Mat mask(48, 64, CV_8UC1, cv::Scalar(0));
  mask(cv::Rect(0, 0, 32, 48)).setTo(255);  // left half: a person
  CullingScore score(dir / "masks");
  score.add("rgb/100.5.jpg", {}, {});  // the mask is read when the score is asked for: written below
  ASSERT_TRUE(cv::imwrite((dir / "masks" / "100.5.png").string(), mask));

  // Left (dynamic) dropped: tp; left kept: fn; right dropped: fp; right kept: tn; a point past the
  // border clamps onto the last column (static).
  const std::vector<cv::KeyPoint> kps{{10.f, 10.f, 7.f}, {20.4f, 30.f, 7.f}, {50.f, 5.f, 7.f},
                                      {40.f, 40.f, 7.f}, {31.4f, 1.f, 7.f},  {90.f, 60.f, 7.f}};
  const std::vector<bool> dropped{true, false, true, false, true, false};
  score.add("rgb/100.5.jpg", kps, dropped);
  score.add("rgb/200.0.jpg", kps, dropped);  // no mask: not counted

  const nlohmann::json j = score.to_json();
  EXPECT_EQ(j["frames"], 2);  // 100.5 twice (once without keypoints)
  EXPECT_EQ(j["tp"], 2);      // (10,10) and (31.4,1) -> column 31, inside the left half
  EXPECT_EQ(j["fn"], 1);
  EXPECT_EQ(j["fp"], 1);
  EXPECT_EQ(j["tn"], 2);
  EXPECT_DOUBLE_EQ(score.precision(), 2.0 / 3.0);
  EXPECT_DOUBLE_EQ(score.recall(), 2.0 / 3.0);
  // Asking again does not count the frames twice.
  EXPECT_EQ(score.to_json()["tp"], 2);
}

}  // namespace
}  // namespace sp::pipeline
