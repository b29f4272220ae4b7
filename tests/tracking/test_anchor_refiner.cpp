// The anchor refiner alone, on generated images: an anchor keyframe image and a current image that is
// the same texture shifted by a known sub-pixel amount. Detections are the true positions rounded to
// whole pixels (what an integer-pixel detector reports); refined positions must recover the true
// sub-pixel ones, and the rules that forbid a patch alignment (occlusion, roll, suspects) must hold.
#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgproc.hpp>
#include <random>

#include "stillpoint/tracking/anchor_refiner.hpp"

namespace sp::track {
namespace {

constexpr double kDepth = 2.0;
const cv::Point2f kShift(0.4f, -0.3f);  // px, the current image is the anchor moved by this

cv::Mat texture(int width, int height, unsigned seed) {
  cv::Mat noise(height, width, CV_32F);
  cv::RNG rng(seed);
  rng.fill(noise, cv::RNG::UNIFORM, 0.0, 255.0);
  cv::Mat smooth;
  cv::GaussianBlur(noise, smooth, cv::Size(0, 0), 2.0);
  cv::normalize(smooth, smooth, 0, 255, cv::NORM_MINMAX);
  cv::Mat out;
  smooth.convertTo(out, CV_8U);
  return out;
}

cv::Mat shifted(const cv::Mat& image, cv::Point2f shift) {
  const cv::Mat A = (cv::Mat_<double>(2, 3) << 1, 0, shift.x, 0, 1, shift.y);
  cv::Mat out;
  cv::warpAffine(image, out, A, image.size(), cv::INTER_CUBIC, cv::BORDER_REFLECT);
  return out;
}

class AnchorRefinerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    anchor_image_ = texture(cam_.width, cam_.height, 7);
    // A grid of features away from the border, all at kDepth in front of the anchor camera (at the
    // world origin), each a map point observed by the anchor keyframe.
    for (int y = 60; y < cam_.height - 60; y += 40) {
      for (int x = 60; x < cam_.width - 60; x += 40) anchor_pts_.emplace_back(x + 0.25f, y + 0.5f);
    }
    Frame anchor = frame_at(anchor_pts_, anchor_image_, geo::SE3());
    map::MapView view = map_.view();
    map::Keyframe kf;
    kf.T_cw = anchor.T_cw;
    kf.features = anchor.features;
    kf.points.assign(anchor.features.size(), map::kNoPoint);
    anchor_id_ = view.add_keyframe(std::move(kf));
    for (std::size_t i = 0; i < anchor_pts_.size(); ++i) {
      map::MapPoint p;
      p.position = cam_.unproject({anchor_pts_[i].x, anchor_pts_[i].y}, kDepth);
      p.descriptor = cv::Mat::zeros(1, 32, CV_8U);
      const map::PointId pid = view.add_point(std::move(p));
      view.add_observation(pid, anchor_id_, static_cast<int>(i));
      points_.push_back(pid);
    }
    anchor_frame_ = std::move(anchor);
  }

  Frame frame_at(const std::vector<cv::Point2f>& pts, const cv::Mat& gray, const geo::SE3& T_cw) const {
    Frame f;
    f.gray = gray;
    f.T_cw = T_cw;
    f.has_pose = true;
    for (const cv::Point2f& p : pts) {
      f.features.keypoints.emplace_back(p, 7.f, -1.f, 0.f, 0);
      f.features.depth.push_back(static_cast<float>(kDepth));
      f.features.u_right.push_back(p.x - static_cast<float>(bf_ / kDepth));
    }
    f.features.descriptors = cv::Mat::zeros(static_cast<int>(pts.size()), 32, CV_8U);
    f.reset_matches();
    return f;
  }

  // What the tracker copies for the refiner under its short read: the frame's points and the anchors'
  // poses. The refiner itself never takes the map lock.
  LocalMapSnapshot snapshot(const AnchorRefiner& refiner, const Frame& f) {
    LocalMapSnapshot s;
    s.reset(refiner.anchor_ids());
    map::MapReader view = map_.reader();
    for (map::PointId pid : f.points) {
      if (pid != map::kNoPoint) s.add(view, pid);
    }
    for (map::KeyframeId a : refiner.anchor_ids()) s.add_pose(view, a);
    return s;
  }

  // The current frame: the texture moved by kShift, detections rounded to whole pixels, every feature
  // matched to its map point. The pose is the anchor's (the refiner only checks its geometry rules).
  Frame current(const cv::Mat& image, const geo::SE3& T_cw = geo::SE3()) const {
    std::vector<cv::Point2f> detected;
    for (const cv::Point2f& p : anchor_pts_)
      detected.emplace_back(std::round(p.x + kShift.x), std::round(p.y + kShift.y));
    Frame f = frame_at(detected, image, T_cw);
    f.points = points_;
    return f;
  }

  geo::CameraIntrinsics cam_;
  double bf_ = 40.0;
  map::Map map_;
  cv::Mat anchor_image_;
  std::vector<cv::Point2f> anchor_pts_;
  std::vector<map::PointId> points_;
  map::KeyframeId anchor_id_ = map::kNoKeyframe;
  Frame anchor_frame_;
};

TEST_F(AnchorRefinerTest, RecoversTheSubPixelShiftOfEveryFeature) {
  AnchorRefiner refiner({}, cam_, map::ScalePyramid::make(8, 1.2));
  refiner.set_anchor(anchor_id_, anchor_frame_);
  Frame f = current(shifted(anchor_image_, kShift));
  const std::vector<float> u_right_before = f.features.u_right;
  std::vector<bool> refined;
  const int moved = refiner.refine(snapshot(refiner, f), f, refined);
  ASSERT_EQ(moved, static_cast<int>(anchor_pts_.size()));
  double sum_sq_before = 0, sum_sq_after = 0;
  for (std::size_t i = 0; i < anchor_pts_.size(); ++i) {
    const cv::Point2f truth = anchor_pts_[i] + kShift;
    const cv::Point2f rounded(std::round(truth.x), std::round(truth.y));
    EXPECT_TRUE(refined[i]);
    // Rounding was off by up to 0.5 px per axis; alignment brings every feature within 0.1 px.
    EXPECT_NEAR(f.features.keypoints[i].pt.x, truth.x, 0.1) << i;
    EXPECT_NEAR(f.features.keypoints[i].pt.y, truth.y, 0.1) << i;
    const cv::Point2f before = rounded - truth, after = f.features.keypoints[i].pt - truth;
    sum_sq_before += before.dot(before);
    sum_sq_after += after.dot(after);
    // The virtual right coordinate moves with u (the same point seen at the same depth).
    EXPECT_NEAR(f.features.u_right[i] - u_right_before[i], f.features.keypoints[i].pt.x - rounded.x, 1e-4);
  }
  EXPECT_EQ(refiner.stats().refined, anchor_pts_.size());
  // Over all features: at least five times closer to the truth than the whole-pixel detections.
  EXPECT_LT(std::sqrt(sum_sq_after), 0.2 * std::sqrt(sum_sq_before));
}

TEST_F(AnchorRefinerTest, AnOccludedPatchKeepsItsDetection) {
  AnchorRefiner refiner({}, cam_, map::ScalePyramid::make(8, 1.2));
  refiner.set_anchor(anchor_id_, anchor_frame_);
  cv::Mat image = shifted(anchor_image_, kShift);
  // Another texture (a person walking in) covers the left third of the image.
  texture(cam_.width, cam_.height, 99)(cv::Rect(0, 0, cam_.width / 3, cam_.height))
      .copyTo(image(cv::Rect(0, 0, cam_.width / 3, cam_.height)));
  Frame f = current(image);
  const std::vector<cv::KeyPoint> detected = f.features.keypoints;
  std::vector<bool> refined;
  refiner.refine(snapshot(refiner, f), f, refined);
  int covered = 0;
  for (std::size_t i = 0; i < anchor_pts_.size(); ++i) {
    if (anchor_pts_[i].x > cam_.width / 3.0 - 12) {
      EXPECT_TRUE(refined[i]) << i;  // visible: aligned
      continue;
    }
    ++covered;
    EXPECT_FALSE(refined[i]) << i;
    EXPECT_EQ(f.features.keypoints[i].pt, detected[i].pt) << i;
  }
  EXPECT_GT(covered, 0);
}

TEST_F(AnchorRefinerTest, NoAlignmentAfterARollOrForSuspectsOrOutliers) {
  AnchorRefiner refiner({}, cam_, map::ScalePyramid::make(8, 1.2));
  refiner.set_anchor(anchor_id_, anchor_frame_);
  std::vector<bool> refined;
  {
    // 10 deg about the optical axis: a translation-only patch alignment is not valid.
    const geo::SE3 rolled(
        Eigen::Quaterniond(Eigen::AngleAxisd(10.0 * M_PI / 180.0, Eigen::Vector3d::UnitZ())),
        Eigen::Vector3d::Zero());
    Frame f = current(shifted(anchor_image_, kShift), rolled);
    EXPECT_EQ(refiner.refine(snapshot(refiner, f), f, refined), 0);
  }
  {
    Frame f = current(shifted(anchor_image_, kShift));
    f.suspect.assign(f.features.size(), false);
    f.suspect[0] = true;  // near a detected person
    f.outlier[1] = true;  // rejected by the pose optimisation
    const int moved = refiner.refine(snapshot(refiner, f), f, refined);
    EXPECT_EQ(moved, static_cast<int>(anchor_pts_.size()) - 2);
    EXPECT_FALSE(refined[0]);
    EXPECT_FALSE(refined[1]);
    EXPECT_TRUE(refined[2]);
  }
  {
    // The camera moved 30 cm closer: every point's depth changed by 15 %, beyond max_scale_change.
    Frame f = current(shifted(anchor_image_, kShift), geo::SE3(Eigen::Quaterniond::Identity(), {0, 0, -0.3}));
    EXPECT_EQ(refiner.refine(snapshot(refiner, f), f, refined), 0);
  }
}

TEST_F(AnchorRefinerTest, DisabledOrWithoutAnchorItDoesNothing) {
  AnchorRefinerConfig off;
  off.enabled = false;
  AnchorRefiner refiner(off, cam_, map::ScalePyramid::make(8, 1.2));
  refiner.set_anchor(anchor_id_, anchor_frame_);
  EXPECT_EQ(refiner.anchors(), 0u);
  Frame f = current(shifted(anchor_image_, kShift));
  std::vector<bool> refined;
  EXPECT_EQ(refiner.refine(snapshot(refiner, f), f, refined), 0);
}

// The rule for the pose solve after the alignment: aligned features alone only near an anchor (both
// distances) and with enough of them; never without an anchor or with the rule off.
TEST_F(AnchorRefinerTest, AlignedFeaturesAloneOnlyNearAnAnchorAndWhenEnough) {
  AnchorRefinerConfig c;
  c.aligned_only_min = 50;
  c.aligned_only_max_translation_m = 0.02;
  c.aligned_only_max_rotation_deg = 1.0;
  AnchorRefiner refiner(c, cam_, map::ScalePyramid::make(8, 1.2));
  const Frame f = current(shifted(anchor_image_, kShift));
  EXPECT_FALSE(refiner.aligned_only(snapshot(refiner, f), geo::SE3(), 100)) << "no anchor yet";
  refiner.set_anchor(anchor_id_, anchor_frame_);
  const LocalMapSnapshot s = snapshot(refiner, f);
  const auto moved = [](double x_m, double yaw_deg) {
    const double a = yaw_deg * M_PI / 180.0;
    // T_cw of a camera whose centre is at (x_m, 0, 0), turned by yaw_deg about its y axis.
    const geo::SE3 T_wc(Eigen::AngleAxisd(a, Eigen::Vector3d::UnitY()).toRotationMatrix(),
                        Eigen::Vector3d(x_m, 0, 0));
    return T_wc.inverse();
  };
  EXPECT_TRUE(refiner.aligned_only(s, moved(0.0, 0.0), 50));
  EXPECT_FALSE(refiner.aligned_only(s, moved(0.0, 0.0), 49)) << "too few aligned";
  EXPECT_TRUE(refiner.aligned_only(s, moved(0.019, 0.9), 200));
  EXPECT_FALSE(refiner.aligned_only(s, moved(0.021, 0.0), 200)) << "camera centre 2.1 cm away";
  EXPECT_FALSE(refiner.aligned_only(s, moved(0.0, 1.1), 200)) << "turned 1.1 deg";
  AnchorRefinerConfig never = c;
  never.aligned_only_min = 0;
  AnchorRefiner off(never, cam_, map::ScalePyramid::make(8, 1.2));
  off.set_anchor(anchor_id_, anchor_frame_);
  EXPECT_FALSE(off.aligned_only(snapshot(off, f), geo::SE3(), 200));
}

TEST(AnchorRefinerConfig, KeysAreReadAndRangeChecked) {
  const AnchorRefinerConfig c = AnchorRefinerConfig::from_yaml(ConfigReader::from_string(
      "anchors: 2\nwindow: 15\nmax_shift: 2\nlevel0_weight: false\naligned_only_min: 80\n"
      "aligned_only_max_translation_m: 0.01\naligned_only_max_rotation_deg: 0.5\n"
      "aligned_only_unaligned: tracked\n",
      "subpixel.yaml"));
  EXPECT_EQ(c.anchors, 2);
  EXPECT_EQ(c.window, 15);
  EXPECT_DOUBLE_EQ(c.max_shift, 2.0);
  EXPECT_FALSE(c.level0_weight);
  EXPECT_EQ(c.aligned_only_min, 80);
  EXPECT_DOUBLE_EQ(c.aligned_only_max_translation_m, 0.01);
  EXPECT_DOUBLE_EQ(c.aligned_only_max_rotation_deg, 0.5);
  EXPECT_EQ(c.aligned_only_unaligned, "tracked");
  EXPECT_THROW(AnchorRefinerConfig::from_yaml(
                   ConfigReader::from_string("aligned_only_unaligned: dropped\n", "subpixel.yaml")),
               std::exception);
  EXPECT_THROW(AnchorRefinerConfig::from_yaml(ConfigReader::from_string("window: 2\n", "subpixel.yaml")),
               std::exception);
  EXPECT_THROW(AnchorRefinerConfig::from_yaml(
                   ConfigReader::from_string("aligned_only_max_translation_m: -1\n", "subpixel.yaml")),
               std::exception);
}

}  // namespace
}  // namespace sp::track
