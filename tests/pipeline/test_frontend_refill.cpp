// The front end's refill alone, on a generated image: a richly textured "person" box takes most of the
// ORB budget, culling drops its features, and the refill must find new ones only on the poor static
// background: never inside the dynamic box, never on a kept feature, all flagged keep.
#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "stillpoint/pipeline/frontend.hpp"

namespace sp::pipeline {
namespace {

io::FrameData scene() {
  io::FrameData d;
  d.bgr = cv::Mat(480, 640, CV_8UC3, cv::Scalar(120, 120, 120));
  cv::RNG rng(3);
  // Sparse, weak background texture: a few soft blobs.
  for (int k = 0; k < 120; ++k) {
    const cv::Point c(rng.uniform(10, 630), rng.uniform(10, 470));
    const int g = rng.uniform(90, 150);
    cv::circle(d.bgr, c, rng.uniform(3, 8), cv::Scalar(g, g, g), cv::FILLED);
  }
  // The "person": dense high-contrast texture in a box.
  cv::Mat person(d.bgr, cv::Rect(200, 100, 240, 300));
  for (int k = 0; k < 1500; ++k) {
    const cv::Point c(rng.uniform(0, 240), rng.uniform(0, 300));
    const int g = rng.uniform(0, 2) * 255;
    cv::circle(person, c, rng.uniform(1, 4), cv::Scalar(g, g, g), cv::FILLED);
  }
  d.depth = cv::Mat(480, 640, CV_32F, cv::Scalar(2.0f));
  return d;
}

TEST(FrontEndRefill, NewFeaturesGoToTheStaticPartOnly) {
  FrontEnd fe(feat::OrbConfig{}, geo::CameraIntrinsics{}, track::DepthModel{});
  const io::FrameData data = scene();
  ExtractedFeatures f = fe.extract(data);
  const cv::Rect2f box(200, 100, 240, 300);
  std::vector<bool> drop(f.keypoints.size(), false);
  std::size_t dropped = 0;
  for (std::size_t i = 0; i < f.keypoints.size(); ++i) {
    if (box.contains(f.keypoints[i].pt)) {
      drop[i] = true;
      ++dropped;
    }
  }
  ASSERT_GT(dropped, f.keypoints.size() / 2) << "the person must take most of the budget for this test";
  const std::size_t kept_before = f.keypoints.size() - dropped;
  const std::vector<cv::KeyPoint> original = f.keypoints;
  std::vector<bool> suspect(f.keypoints.size(), false);
  const std::size_t added = fe.refill(f, drop, suspect, {box});
  // The freed budget finds static corners culling had left undetected: at least 20 % more static
  // features (no refill adds none). Re-selecting among the first pass's corners (the default) finds
  // fewer than a second FAST pass, which retries cells emptied by the mask with the low threshold.
  EXPECT_GT(static_cast<double>(kept_before + added), 1.2 * static_cast<double>(kept_before));
  {
    ExtractedFeatures g = fe.extract(data);
    std::vector<bool> gdrop(g.keypoints.size(), false), gsuspect(g.keypoints.size(), false);
    for (std::size_t i = 0; i < g.keypoints.size(); ++i) gdrop[i] = box.contains(g.keypoints[i].pt);
    const std::size_t fresh = fe.refill(g, gdrop, gsuspect, {box}, {0, false});
    EXPECT_GT(static_cast<double>(kept_before + fresh), 1.3 * static_cast<double>(kept_before));
  }
  ASSERT_EQ(f.keypoints.size(), original.size() + added);
  ASSERT_EQ(drop.size(), f.keypoints.size());
  ASSERT_EQ(suspect.size(), f.keypoints.size());
  ASSERT_EQ(f.descriptors.rows, static_cast<int>(f.keypoints.size()));
  for (std::size_t i = original.size(); i < f.keypoints.size(); ++i) {
    const cv::Point2f p = f.keypoints[i].pt;
    EXPECT_FALSE(drop[i]);
    EXPECT_FALSE(suspect[i]);
    EXPECT_FALSE(box.contains(p)) << p;
    for (std::size_t j = 0; j < original.size(); ++j) {
      if (drop[j]) continue;
      EXPECT_GT(cv::norm(original[j].pt - p), 2.0) << "refilled on top of kept feature " << j;
    }
  }
  // The frame built from it keeps the kept and the refilled features.
  const track::Frame frame = fe.assemble(data, f, drop, suspect);
  EXPECT_EQ(frame.features.size(), kept_before + added);
}

// With a budget of the removed count, the frame regains about its ORB budget and no more.
TEST(FrontEndRefill, BudgetOfTheRemovedCount) {
  FrontEnd fe(feat::OrbConfig{}, geo::CameraIntrinsics{}, track::DepthModel{});
  const io::FrameData data = scene();
  const cv::Rect2f box(200, 100, 240, 300);
  for (const bool reuse : {true, false}) {
    ExtractedFeatures f = fe.extract(data);
    std::vector<bool> drop(f.keypoints.size(), false), suspect(f.keypoints.size(), false);
    std::size_t dropped = 0;
    for (std::size_t i = 0; i < f.keypoints.size(); ++i) {
      drop[i] = box.contains(f.keypoints[i].pt);
      dropped += drop[i] ? 1 : 0;
    }
    const std::size_t budget = dropped / 4;
    const std::size_t added = fe.refill(f, drop, suspect, {box}, {static_cast<int>(budget), reuse});
    EXPECT_LE(added, budget + 5) << "reuse " << reuse;  // per-level rounding
    EXPECT_GT(added, budget / 2) << "reuse " << reuse;
    for (std::size_t i = f.keypoints.size() - added; i < f.keypoints.size(); ++i)
      EXPECT_FALSE(box.contains(f.keypoints[i].pt)) << "reuse " << reuse;
  }
}

}  // namespace
}  // namespace sp::pipeline
