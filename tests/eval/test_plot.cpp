#include <gtest/gtest.h>

#include <opencv2/imgcodecs.hpp>

#include "../support/shared_data.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/eval/evaluate.hpp"
#include "stillpoint/io/trajectory_io.hpp"

namespace sp::eval {
namespace {

int count_colour(const cv::Mat& img, const cv::Vec3b& bgr) {
  int n = 0;
  for (int y = 0; y < img.rows; ++y) {
    for (int x = 0; x < img.cols; ++x) n += img.at<cv::Vec3b>(y, x) == bgr;
  }
  return n;
}

TEST(Plot, DrawsBothTrajectoriesAndTheErrors) {
  SP_REQUIRE_SHARED(SP_SHARED_DIR "/data/eval/case_a/gt.txt", SP_SHARED_DIR "/data/eval/case_a/est.txt");
  const std::filesystem::path dir = SP_SHARED_DIR "/data/eval/case_a";
  const auto r =
      evaluate(io::read_tum_trajectory(dir / "gt.txt"), io::read_tum_trajectory(dir / "est.txt"), {});
  const std::filesystem::path png = std::filesystem::path(SP_TEST_TMP_DIR) / "eval" / "case_a.png";
  std::filesystem::remove(png);
  write_plot(png, r);
  const cv::Mat img = cv::imread(png.string(), cv::IMREAD_COLOR);
  ASSERT_FALSE(img.empty());
  EXPECT_EQ(img.cols, 1000);
  EXPECT_GT(img.rows, 700);
  // Pure colours of the line styles: ground truth, estimate, ATE error.
  EXPECT_GT(count_colour(img, {40, 40, 40}), 500);
  EXPECT_GT(count_colour(img, {200, 110, 20}), 500);
  EXPECT_GT(count_colour(img, {80, 80, 235}), 500);
  // Mostly white background: the plot is not a blob.
  EXPECT_GT(count_colour(img, {255, 255, 255}), img.rows * img.cols / 2);
}

TEST(Plot, EmptyResultIsAnError) { EXPECT_THROW(write_plot("/tmp/unused.png", EvalResult{}), Error); }

}  // namespace
}  // namespace sp::eval
