#include <gtest/gtest.h>

#include <algorithm>
#include <opencv2/imgproc.hpp>
#include <random>

#include "stillpoint/features/orb_extractor.hpp"
#include "stillpoint/features/quadtree.hpp"

namespace sp::feat {
namespace {

cv::KeyPoint kp(float x, float y, float response) { return cv::KeyPoint(x, y, 31.f, -1.f, response); }

TEST(Quadtree, PrefersSpreadOverStrength) {
  // 400 strong points packed in a 40x40 corner, 60 weak points spread over the rest of the image.
  std::vector<cv::KeyPoint> kps;
  for (int i = 0; i < 400; ++i)
    kps.push_back(kp(static_cast<float>(i % 20) * 2.f, static_cast<float>(i / 20) * 2.f,
                     100.f + static_cast<float>(i)));
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> ux(100.f, 639.f), uy(100.f, 479.f);
  for (int i = 0; i < 60; ++i) kps.push_back(kp(std::floor(ux(rng)), std::floor(uy(rng)), 10.f));
  QuadtreeScratch scratch;
  std::vector<cv::KeyPoint> out;
  distribute_quadtree(kps, 100, 0.f, 0.f, 640.f, 480.f, out, scratch);
  ASSERT_LE(out.size(), 100u);
  EXPECT_GE(out.size(), 90u);
  const auto weak =
      std::count_if(out.begin(), out.end(), [](const cv::KeyPoint& k) { return k.response == 10.f; });
  // Top-100 by response would take no weak point; the tree keeps most of the spread ones.
  EXPECT_GE(weak, 45);
  RecordProperty("weak_kept", static_cast<int>(weak));
  // The strongest point always survives (it wins its leaf), and the output is sorted by response.
  EXPECT_EQ(out.front().response, 499.f);
  for (std::size_t i = 1; i < out.size(); ++i) EXPECT_GE(out[i - 1].response, out[i].response);
}

TEST(Quadtree, OnePerLeafAndDeterministic) {
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> ux(0.f, 639.f), uy(0.f, 479.f), ur(1.f, 50.f);
  std::vector<cv::KeyPoint> kps;
  for (int i = 0; i < 2000; ++i)
    kps.push_back(kp(std::floor(ux(rng)), std::floor(uy(rng)), std::floor(ur(rng))));
  QuadtreeScratch s1, s2;
  std::vector<cv::KeyPoint> a, b, few;
  distribute_quadtree(kps, 217, 0.f, 0.f, 640.f, 480.f, a, s1);
  std::vector<cv::KeyPoint> reversed(kps.rbegin(), kps.rend());
  distribute_quadtree(reversed, 217, 0.f, 0.f, 640.f, 480.f, b, s2);
  ASSERT_EQ(a.size(), 217u);
  ASSERT_EQ(a.size(), b.size());  // the input order does not matter
  for (std::size_t i = 0; i < a.size(); ++i) EXPECT_EQ(a[i].pt, b[i].pt);
  // Fewer points than wanted: all of them come back.
  std::vector<cv::KeyPoint> some(kps.begin(), kps.begin() + 50);
  distribute_quadtree(some, 217, 0.f, 0.f, 640.f, 480.f, few, s1);
  EXPECT_EQ(few.size(), 50u);
  // Points outside the region are ignored; an empty input gives nothing.
  distribute_quadtree({kp(700.f, 10.f, 5.f)}, 10, 0.f, 0.f, 640.f, 480.f, few, s1);
  EXPECT_TRUE(few.empty());
  // A wide region starts from several roots and still reaches the target.
  distribute_quadtree(kps, 100, 0.f, 0.f, 640.f, 160.f, few, s1);
  EXPECT_EQ(few.size(), 100u);
}

TEST(OrbExtractorShapes, SmallWideAndRoiImages) {
  cv::Mat noise(200, 1200, CV_8UC1);
  cv::RNG rng(1);
  rng.fill(noise, cv::RNG::UNIFORM, 0, 256);
  cv::GaussianBlur(noise, noise, cv::Size(5, 5), 1.5);
  OrbExtractor orb(OrbConfig{});
  std::vector<cv::KeyPoint> kps;
  cv::Mat desc;
  orb.extract(noise, kps, desc);  // wide: several quadtree roots
  EXPECT_GT(kps.size(), 900u);
  EXPECT_LE(kps.size(), 1000u);
  // A non-contiguous ROI gives the same result as its copy.
  const cv::Mat roi = noise(cv::Rect(100, 20, 300, 150));
  std::vector<cv::KeyPoint> k1, k2;
  cv::Mat d1, d2;
  orb.extract(roi, k1, d1);
  orb.extract(roi.clone(), k2, d2);
  ASSERT_EQ(k1.size(), k2.size());
  EXPECT_EQ(cv::norm(d1, d2, cv::NORM_L1), 0.0);
  for (const auto& k : k1) {
    EXPECT_LT(k.pt.x, 300.f);
    EXPECT_LT(k.pt.y, 150.f);
  }
  // Smaller than a patch at every level: no keypoints, no crash.
  orb.extract(noise(cv::Rect(0, 0, 20, 20)), kps, desc);
  EXPECT_TRUE(kps.empty());
  EXPECT_EQ(desc.rows, 0);
}

}  // namespace
}  // namespace sp::feat
