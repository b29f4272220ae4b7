// MapView::append_features: features seen when a keyframe was made but mapped later (a person proven
// still, docs/dynamic.md "A last resort is never mapped") join the keyframe without moving the ones
// it has, so observations and copies other stages hold keep pointing at the same features.
#include <gtest/gtest.h>

#include "stillpoint/common/error.hpp"
#include "stillpoint/map/map.hpp"

namespace sp::map {
namespace {

FeatureSet features_at(const std::vector<cv::Point2f>& points, std::uint8_t first_byte) {
  FeatureSet f;
  f.descriptors = cv::Mat::zeros(static_cast<int>(points.size()), 32, CV_8U);
  for (std::size_t i = 0; i < points.size(); ++i) {
    f.keypoints.emplace_back(points[i], 31.f);
    f.depth.push_back(1.0f + static_cast<float>(i));
    f.u_right.push_back(points[i].x - 40.f);
    f.descriptors.at<std::uint8_t>(static_cast<int>(i), 0) = static_cast<std::uint8_t>(first_byte + i);
  }
  return f;
}

TEST(AppendFeatures, NewFeaturesFollowTheOldOnesWithEmptySlotsAndAreFoundByTheGrid) {
  Map map;
  MapView view = map.view();
  Keyframe kf;
  kf.features = features_at({{10, 10}, {600, 400}}, 1);
  kf.index = make_feature_grid(kf.features.keypoints, 640, 480);
  const KeyframeId kid = view.add_keyframe(kf);
  const PointId pid = view.add_point(MapPoint{});
  view.add_observation(pid, kid, 1);
  const cv::Mat old_descriptors = view.keyframe(kid)->features.descriptors;

  const auto first =
      view.append_features(kid, features_at({{300, 200}, {310, 205}, {50, 450}}, 100), cv::Size(640, 480));
  ASSERT_TRUE(first.has_value());
  EXPECT_EQ(*first, 2u);
  const Keyframe* k = view.keyframe(kid);
  ASSERT_EQ(k->features.size(), 5u);
  ASSERT_EQ(k->points.size(), 5u);
  ASSERT_EQ(k->features.depth.size(), 5u);
  ASSERT_EQ(k->features.u_right.size(), 5u);
  ASSERT_EQ(k->features.descriptors.rows, 5);
  // The old features and their point stay where they were; the new ones follow in order, unmatched.
  EXPECT_EQ(k->points[1], pid);
  EXPECT_EQ(k->features.keypoints[1].pt, cv::Point2f(600, 400));
  EXPECT_EQ(k->features.descriptors.at<std::uint8_t>(1, 0), 2);
  for (std::size_t i = 2; i < 5; ++i) {
    EXPECT_EQ(k->points[i], kNoPoint) << i;
    EXPECT_EQ(k->features.descriptors.at<std::uint8_t>(static_cast<int>(i), 0), 100 + (i - 2)) << i;
  }
  EXPECT_FLOAT_EQ(k->features.depth[4], 3.0f);
  // A copy of the descriptors taken before keeps its rows (a new buffer was made).
  EXPECT_EQ(old_descriptors.rows, 2);
  EXPECT_EQ(old_descriptors.at<std::uint8_t>(0, 0), 1);
  // The grid covers the new features.
  const std::vector<std::size_t> near = k->index.in_area(305, 202, 10);
  EXPECT_EQ(near, (std::vector<std::size_t>{2, 3}));
  // The new slots take observations.
  const PointId later = view.add_point(MapPoint{});
  view.add_observation(later, kid, 4);
  EXPECT_EQ(view.keyframe(kid)->points[4], later);
}

TEST(AppendFeatures, RefusesACulledOrMissingKeyframeAndInconsistentArrays) {
  Map map;
  MapView view = map.view();
  Keyframe kf;
  kf.features = features_at({{10, 10}}, 1);
  const KeyframeId root = view.add_keyframe(kf);
  const KeyframeId second = view.add_keyframe(kf);
  view.keyframe(second)->bad = true;  // culled
  const FeatureSet extra = features_at({{20, 20}}, 9);
  EXPECT_FALSE(view.append_features(second, extra, cv::Size(640, 480)).has_value());
  EXPECT_FALSE(view.append_features(KeyframeId{99}, extra, cv::Size(640, 480)).has_value());
  FeatureSet broken = extra;
  broken.depth.clear();
  EXPECT_THROW((void)view.append_features(root, broken, cv::Size(640, 480)), Error);
  EXPECT_EQ(view.keyframe(root)->features.size(), 1u);
}

}  // namespace
}  // namespace sp::map
