// The relocalisation database on a small hand-made map: keyframes with random ORB-like descriptors,
// BoW vectors from the shipped vocabulary. A keyframe's own descriptors find it first; a keyframe the
// map culls (or purges) is erased by erase_culled and no longer returned; a frame without features
// finds nothing.
#include <gtest/gtest.h>

#include <random>

#include "stillpoint/pipeline/relocalization_index.hpp"

namespace sp::pipeline {
namespace {

cv::Mat random_descriptors(int n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> byte(0, 255);
  cv::Mat d(n, 32, CV_8U);
  for (int i = 0; i < n; ++i)
    for (int b = 0; b < 32; ++b) d.at<std::uint8_t>(i, b) = static_cast<std::uint8_t>(byte(rng));
  return d;
}

class RelocalizationIndexTest : public ::testing::Test {
 protected:
  void SetUp() override {
    vocabulary_ = std::make_shared<const loop::Vocabulary>(loop::Vocabulary::load(
        std::filesystem::path(SP_SOURCE_DIR) / "data" / "vocab" / "stillpoint_orb.spv"));
    map::MapView view = map_.view();
    for (unsigned k = 0; k < 4; ++k) {
      map::Keyframe kf;
      kf.features.descriptors = random_descriptors(400, 10 + k);
      kf.features.keypoints.resize(400);
      kf.features.depth.assign(400, 1.0f);
      kf.features.u_right.assign(400, -1.0f);
      kf.points.assign(400, map::kNoPoint);
      kf.parent = ids_.empty() ? map::kNoKeyframe : ids_.back();  // the root is never culled
      ids_.push_back(view.add_keyframe(std::move(kf)));
    }
  }
  cv::Mat descriptors(map::KeyframeId id) {
    map::MapView view = map_.view();
    return view.keyframe(id)->features.descriptors.clone();
  }

  std::shared_ptr<const loop::Vocabulary> vocabulary_;
  map::Map map_;
  std::vector<map::KeyframeId> ids_;
};

TEST_F(RelocalizationIndexTest, FindsTheKeyframeAndForgetsCulledOnes) {
  RelocalizationIndex index(vocabulary_);
  for (map::KeyframeId id : ids_) index.add(id, index.describe(descriptors(id)));
  EXPECT_EQ(index.size(), 4u);
  // A frame that sees what keyframe 3 saw (a third of its features dropped): keyframe 3 first.
  const cv::Mat query = descriptors(ids_[2]).rowRange(0, 270).clone();
  auto found = index.candidates(query, 10);
  ASSERT_FALSE(found.empty());
  EXPECT_EQ(found.front(), ids_[2]);
  EXPECT_EQ(index.candidates(query, 1).size(), 1u);

  {
    map::MapView view = map_.view();
    EXPECT_TRUE(index.erase_culled(view).empty());  // nothing culled yet
    view.erase_keyframe(ids_[2]);
    EXPECT_EQ(index.erase_culled(view), std::vector<map::KeyframeId>{ids_[2]});
    EXPECT_TRUE(index.erase_culled(view).empty());  // erased once
  }
  EXPECT_EQ(index.size(), 3u);
  found = index.candidates(query, 10);
  EXPECT_EQ(std::find(found.begin(), found.end(), ids_[2]), found.end());

  index.erase(ids_[0]);
  index.erase(ids_[0]);  // unknown now: ignored
  EXPECT_EQ(index.size(), 2u);
  const RelocalizationIndexStats s = index.stats();
  EXPECT_EQ(s.filed, 4u);
  EXPECT_EQ(s.erased, 2u);
  EXPECT_EQ(s.queries, 3u);
}

TEST_F(RelocalizationIndexTest, ABlackFrameFindsNothingAndIsNotAQuery) {
  RelocalizationIndex index(vocabulary_);
  for (map::KeyframeId id : ids_) index.add(id, index.describe(descriptors(id)));
  EXPECT_TRUE(index.candidates(cv::Mat(0, 32, CV_8U), 10).empty());
  EXPECT_EQ(index.stats().queries, 0u);
}

TEST_F(RelocalizationIndexTest, RefilingAKeyframeReplacesItsVector) {
  RelocalizationIndex index(vocabulary_);
  index.add(ids_[1], index.describe(descriptors(ids_[1])));
  index.add(ids_[1], index.describe(descriptors(ids_[3])));  // same id, another vector
  EXPECT_EQ(index.size(), 1u);
  EXPECT_EQ(index.stats().filed, 1u);
  const auto found = index.candidates(descriptors(ids_[3]), 5);
  ASSERT_EQ(found.size(), 1u);
  EXPECT_EQ(found.front(), ids_[1]);
}

}  // namespace
}  // namespace sp::pipeline
