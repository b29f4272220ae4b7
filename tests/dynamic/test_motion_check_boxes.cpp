// The motion check's boxes on rendered planes: boxes carried between detections, coasted over missed
// detections, snapped to the image border, and the bands around them.
#include <gtest/gtest.h>

#include "motion_check_scene.hpp"
#include "stillpoint/dynamic/decoders.hpp"
#include "stillpoint/dynamic/dynamic_filter.hpp"

namespace sp::dyn {
namespace {

using test::Plane;
using test::Rendered;
using test::run_frames;
using test::Scene;
using test::sequence_input;
using test::still_input;
using test::walking_patch_frames;

TEST(MotionCheck, LateDetectionIsCarriedToTheCurrentFrame) {
  const Scene s;
  const std::vector<Rendered> frames = walking_patch_frames(s, 3, 0.06);
  const auto kps = test::grid_keypoints(640, 480, 8);
  Detections det;  // detected on frame 0, used on frames 1 and 2
  det.frame_index = 0;
  det.items = {{test::label_box(frames[0].label, 2), 0, 0.9f}};
  const DynamicResult r = run_frames(frames, kps, det);
  const cv::Rect2f truth = test::label_box(frames[2].label, 2);
  ASSERT_EQ(r.boxes.size(), 1u);
  EXPECT_LT(iou(det.items[0].box, truth), 0.6f);  // the stale box would be off
  EXPECT_GT(iou(r.boxes[0].box, truth), 0.85f);
  EXPECT_TRUE(r.box_dynamic[0]);
  EXPECT_EQ(r.residual_used, "homography");  // static camera: identity motion
}

// A patch walking towards the static camera (2.0 -> 1.8 -> 1.62 m) grows ~11 % per frame: the box
// detected on frame 0 is carried to frame 2 by the points' median flow and the change of their spread.
TEST(MotionCheck, CarriedBoxFollowsAnApproachingObjectsScale) {
  const Scene s;
  std::vector<Rendered> frames;
  for (double z : {2.0, 1.8, 1.62}) {
    const std::vector<Plane> planes = {{3.0, cv::Rect2d(), 200, &s.wall_tex, 0},
                                       {z, cv::Rect2d(-0.05, -0.2, 0.3, 0.4), 300, &s.patch_tex, 2}};
    frames.push_back(test::render(planes, Eigen::Isometry3d::Identity()));
  }
  const auto kps = test::grid_keypoints(640, 480, 8);
  Detections det;  // detected on frame 0 only
  det.frame_index = 0;
  det.items = {{test::label_box(frames[0].label, 2), 0, 0.9f}};
  const DynamicResult r = run_frames(frames, kps, det);
  const cv::Rect2f truth = test::label_box(frames[2].label, 2);
  ASSERT_EQ(r.boxes.size(), 1u);
  EXPECT_LT(iou(det.items[0].box, truth), 0.75f);  // the stale box is a fifth too small
  EXPECT_GT(iou(r.boxes[0].box, truth), 0.85f);
  EXPECT_NEAR(r.boxes[0].box.width / truth.width, 1.0, 0.08);
}

// A walking person (the patch, boxed as a person) that the detector finds on frames 1-2 and misses
// from frame 3 on: with coast_frames its box is carried by the flow of its points, stays dynamic and
// follows the person for coast_frames frames after the last detection, then ends; without, the person
// is unboxed from the first miss.
TEST(MotionCheck, MissedDetectionOfAMovingPersonIsCoasted) {
  const Scene s;
  const std::vector<Rendered> frames = walking_patch_frames(s, 7, 0.02);
  const auto kps = test::grid_keypoints(640, 480, 8);
  for (int coast : {0, 3}) {
    SCOPED_TRACE(coast);
    MotionCheckConfig cfg;
    cfg.coast_frames = coast;
    DynamicFeatureFilter f(cfg);
    for (std::size_t i = 1; i < frames.size(); ++i) {
      Detections det;
      det.frame_index = i;
      const cv::Rect2f truth = test::label_box(frames[i].label, 2);
      if (i <= 2) det.items = {{truth, 0, 0.9f}};
      const DynamicResult r = f.process(sequence_input(frames, i, &kps, &det, true));
      const bool coasting = i > 2 && static_cast<int>(i - 2) <= coast;
      if (i <= 2 || coasting) {
        ASSERT_EQ(r.boxes.size(), 1u) << "frame " << i;
        EXPECT_TRUE(r.box_dynamic[0]) << "frame " << i;
        // The box follows the person (5.3 px per frame): its centre within 2 px of the truth's.
        const cv::Point2f c = (r.boxes[0].box.tl() + r.boxes[0].box.br()) * 0.5f;
        const cv::Point2f t = (truth.tl() + truth.br()) * 0.5f;
        EXPECT_LT(cv::norm(c - t), 2.0) << "frame " << i;
      } else {
        EXPECT_TRUE(r.boxes.empty()) << "frame " << i;
      }
    }
  }
}

// Feeds frames 1.. to a filter with cfg, each detected with a box that leaves out the patch's top third
// (as a late detection's box can leave out the head of someone close); the last result and the
// patch's true box in the last frame.
DynamicResult run_with_top_third_unboxed(const std::vector<Rendered>& frames,
                                         const std::vector<cv::KeyPoint>& kps, const MotionCheckConfig& cfg,
                                         cv::Rect2f& truth) {
  DynamicFeatureFilter f(cfg);
  DynamicResult r;
  for (std::size_t i = 1; i < frames.size(); ++i) {
    truth = test::label_box(frames[i].label, 2);
    cv::Rect2f cut = truth;
    cut.y += truth.height / 3;
    cut.height -= truth.height / 3;
    Detections det;
    det.frame_index = i;
    det.items = {{cut, 0, 0.9f}};
    r = f.process(sequence_input(frames, i, &kps, &det, true));
  }
  return r;
}

// Keypoints of the person above its box and of the wall in the band around the box (clear of the box's
// 2 x 4 px suspect margin and of the patch's edges): how many, how many culled, how many suspect.
struct BandCounts {
  int person_top = 0, person_top_culled = 0, person_top_suspect = 0;
  int wall = 0, wall_culled = 0, wall_suspect = 0;
};

BandCounts count_band(const DynamicResult& r, const std::vector<cv::KeyPoint>& kps, const cv::Rect2f& truth,
                      double share) {
  const cv::Rect2f& box = r.boxes.at(0).box;
  const float band = static_cast<float>(share) * std::max(box.width, box.height);
  const cv::Rect2f top(truth.x + 6, truth.y + 2, truth.width - 12, box.y - 12 - (truth.y + 2));
  const cv::Rect2f person_grown(truth.x - 6, truth.y - 6, truth.width + 12, truth.height + 12);
  const cv::Rect2f box_grown(box.x - 10, box.y - 10, box.width + 20, box.height + 20);
  const cv::Rect2f band_outer(box.x - band + 2, box.y - band + 2, box.width + 2 * band - 4,
                              box.height + 2 * band - 4);
  BandCounts c;
  for (std::size_t k = 0; k < kps.size(); ++k) {
    const cv::Point2f& p = kps[k].pt;
    if (top.contains(p)) {
      ++c.person_top;
      c.person_top_culled += r.keypoint_dynamic[k] ? 1 : 0;
      c.person_top_suspect += r.keypoint_suspect[k] ? 1 : 0;
    } else if (!person_grown.contains(p) && !box_grown.contains(p) && band_outer.contains(p)) {
      ++c.wall;
      c.wall_culled += r.keypoint_dynamic[k] ? 1 : 0;
      c.wall_suspect += r.keypoint_suspect[k] ? 1 : 0;
    }
  }
  return c;
}

// The band counts after frames of the patch moving `step_m` per frame, with the band switch `band`
// (object_band_share or suspect_band_share) at `share`; unboxed movers are not culled, to test the band
// alone. The box must come out dynamic, with enough of the person's top and of the band's wall to count.
BandCounts band_counts(double step_m, double MotionCheckConfig::*band, double share) {
  const auto kps = test::grid_keypoints(640, 480, 8);
  const std::vector<Rendered> frames = walking_patch_frames(Scene{}, 3, step_m);
  MotionCheckConfig cfg;
  cfg.cull_unboxed_movers = false;
  cfg.*band = share;
  cv::Rect2f truth;
  const DynamicResult r = run_with_top_third_unboxed(frames, kps, cfg, truth);
  EXPECT_EQ(r.boxes.size(), 1u);
  EXPECT_TRUE(!r.box_dynamic.empty() && r.box_dynamic[0]);
  const BandCounts c = r.boxes.size() == 1 ? count_band(r, kps, truth, share) : BandCounts{};
  EXPECT_GT(c.person_top, 20);
  if (share > 0) {
    EXPECT_GT(c.wall, 50);
  }
  return c;
}

// A walking person (the patch at 2 m before the wall at 3 m) whose box leaves out its top third, as a
// late detection's box can leave out the head of someone close: with object_band_share the keypoints
// just outside the box at the person's depth are culled, the wall's keypoints in the same band are not;
// without it the person's top third is kept.
TEST(MotionCheck, KeypointsJustOutsideADynamicBoxAtTheObjectsDepthAreTheObject) {
  for (double share : {0.0, 0.5}) {
    SCOPED_TRACE(share);
    const BandCounts c = band_counts(0.06, &MotionCheckConfig::object_band_share, share);
    EXPECT_EQ(c.person_top_culled, share > 0 ? c.person_top : 0);
    EXPECT_EQ(c.wall_culled, 0);
  }
}

// A person standing still (not yet proven still, so its box is dynamic) whose box leaves out its top
// third: with suspect_band_share those keypoints are kept but marked suspect for the pose guard, the
// wall's keypoints in the band are not; without it neither is (nothing moves, so no keypoint is suspect
// for a moving neighbour).
TEST(MotionCheck, KeypointsJustOutsideADynamicBoxAtTheObjectsDepthAreSuspect) {
  for (double share : {0.0, 0.5}) {
    SCOPED_TRACE(share);
    const BandCounts c = band_counts(0.0, &MotionCheckConfig::suspect_band_share, share);
    EXPECT_EQ(c.person_top_culled, 0);
    EXPECT_EQ(c.person_top_suspect, share > 0 ? c.person_top : 0);
    EXPECT_EQ(c.wall_suspect, 0);
  }
}

// A walking person (a tall patch at 2 m, cut off by the image's top edge) whose detected box stops 20 px
// short of that edge, as a detector's box does for someone cut off by the image: with border_snap_px 24
// the box's top edge moves onto the image's and the person's keypoints above the detected box are culled;
// the box's other edges, far from the image's, stay. Without it those keypoints are kept (unboxed movers
// are not culled here, to test the snap alone).
TEST(MotionCheck, BoxEdgeNearTheImageEdgeIsSnappedOntoIt) {
  const auto kps = test::grid_keypoints(640, 480, 8);
  const Scene s;
  std::vector<Rendered> frames;
  for (double x : {0.0, 0.06, 0.12}) {
    const std::vector<Plane> planes = {{3.0, cv::Rect2d(), 200, &s.wall_tex, 0},
                                       {2.0, cv::Rect2d(0.1 + x, -1.2, 0.4, 1.0), 300, &s.patch_tex, 2}};
    frames.push_back(test::render(planes, Eigen::Isometry3d::Identity()));
  }
  for (double snap : {0.0, 24.0}) {
    SCOPED_TRACE(snap);
    MotionCheckConfig cfg;
    cfg.cull_unboxed_movers = false;
    cfg.border_snap_px = snap;
    DynamicFeatureFilter f(cfg);
    DynamicResult r;
    cv::Rect2f truth, cut;
    for (std::size_t i = 1; i < frames.size(); ++i) {
      truth = test::label_box(frames[i].label, 2);
      ASSERT_EQ(truth.y, 0.f);  // cut off by the image's top edge
      cut = truth;
      cut.y += 20;
      cut.height -= 20;
      Detections det;
      det.frame_index = i;
      det.items = {{cut, 0, 0.9f}};
      r = f.process(sequence_input(frames, i, &kps, &det, true));
    }
    ASSERT_EQ(r.boxes.size(), 1u);
    ASSERT_TRUE(r.box_dynamic[0]);
    const cv::Rect2f& box = r.boxes[0].box;
    EXPECT_EQ(box.y, snap > 0 ? 0.f : cut.y);
    EXPECT_EQ(box.x, cut.x);
    EXPECT_EQ(box.x + box.width, cut.x + cut.width);
    EXPECT_EQ(box.y + box.height, cut.y + cut.height);
    // The person above the detected box (clear of its 4 px margin and of the patch's sides).
    const cv::Rect2f top(truth.x + 6, 0, truth.width - 12, cut.y - 5);
    const test::InRect person_top = test::count_in(top, kps, r.keypoint_dynamic);
    EXPECT_GT(person_top.total, 10);
    EXPECT_EQ(person_top.flagged, snap > 0 ? person_top.total : 0);
  }
}

// A person standing still and not yet proven static (culled as a person) and a chair (a static
// class, kept), both detected on frames 1-2 and missed from frame 3 on. With coast_culled the
// person's box, culled in the frame before, is carried for coast_frames frames after its last
// detection and stays dynamic; the chair, never culled, is not. Coasting only tracks seen moving
// (coast_culled off) leaves the still person unboxed from the first miss.
TEST(MotionCheck, MissedDetectionOfAnUnprovenPersonIsCoastedWhenCulledBoxesCoast) {
  const Scene s;
  const Rendered f = test::render(s.planes({0, 0}), Eigen::Isometry3d::Identity());
  const auto kps = test::grid_keypoints(640, 480, 8);
  const cv::Rect2f person = test::label_box(f.label, 1), chair = test::label_box(f.label, 2);
  for (bool coast_culled : {false, true}) {
    SCOPED_TRACE(coast_culled);
    MotionCheckConfig cfg;
    cfg.coast_frames = 3;
    cfg.coast_culled = coast_culled;
    cfg.static_proof_frames = 8;  // still unproven over the whole run
    DynamicFeatureFilter filter(cfg);
    for (std::size_t i = 1; i <= 6; ++i) {
      Detections det;
      det.frame_index = i;
      if (i <= 2) det.items = {{person, 0, 0.9f}, {chair, 56, 0.9f}};
      const DynamicResult r = filter.process(still_input(f, i, &kps, &det));
      std::size_t person_boxes = 0, chair_boxes = 0;
      for (std::size_t b = 0; b < r.boxes.size(); ++b) {
        if (r.boxes[b].class_id == 56) {
          ++chair_boxes;
          continue;
        }
        ++person_boxes;
        EXPECT_TRUE(r.box_dynamic[b]) << "frame " << i;
        EXPECT_GT(iou(r.boxes[b].box, person), 0.9f) << "frame " << i;  // nobody moves
      }
      const bool coasting = coast_culled && i >= 3 && i <= 5;  // up to 3 frames after frame 2
      EXPECT_EQ(person_boxes, i <= 2 || coasting ? 1u : 0u) << "frame " << i;
      EXPECT_EQ(chair_boxes, i <= 2 ? 1u : 0u) << "frame " << i;
      if (coasting) {
        int culled_in_person = 0;
        for (std::size_t k = 0; k < kps.size(); ++k)
          culled_in_person += r.keypoint_dynamic[k] && person.contains(kps[k].pt) ? 1 : 0;
        EXPECT_GT(culled_in_person, 50) << "frame " << i;
      }
    }
  }
}

}  // namespace
}  // namespace sp::dyn
