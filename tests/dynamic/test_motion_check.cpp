// The motion check on rendered planes with known camera and object motion.
#include <gtest/gtest.h>

#include "motion_check_scene.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/dynamic/decoders.hpp"
#include "stillpoint/dynamic/dynamic_filter.hpp"

namespace sp::dyn {
namespace {

using test::Plane;
using test::Rendered;
using test::Scene;
using test::sequence_input;
using test::still_input;

Eigen::Isometry3d pose(double yaw_deg, const Eigen::Vector3d& c) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(yaw_deg * M_PI / 180, Eigen::Vector3d::UnitY()).toRotationMatrix();
  T.translation() = c;
  return T;
}

struct Shares {
  double moving[3] = {0, 0, 0};
  int count[3] = {0, 0, 0};
  double raw_flow_background = 0;  // median |flow| of wall points, px
};

Shares shares(const DynamicResult& r, const cv::Mat& label) {
  Shares s;
  std::vector<double> flow;
  for (std::size_t i = 0; i < r.flow_points.size(); ++i) {
    const cv::Point p(cvRound(r.flow_points[i].x), cvRound(r.flow_points[i].y));
    const int l = label.at<uchar>(p);
    if (l > 2) continue;
    s.count[l]++;
    s.moving[l] += r.flow_point_moving[i] ? 1 : 0;
    if (l == 0) flow.push_back(cv::norm(r.flow_points[i] - r.flow_prev[i]));
  }
  for (int l = 0; l < 3; ++l) s.moving[l] = s.count[l] ? s.moving[l] / s.count[l] : 0;
  if (!flow.empty()) {
    std::nth_element(flow.begin(), flow.begin() + static_cast<std::ptrdiff_t>(flow.size() / 2), flow.end());
    s.raw_flow_background = flow[flow.size() / 2];
  }
  return s;
}

struct Pair {
  Rendered prev, cur;
  std::vector<cv::KeyPoint> kps = test::grid_keypoints(640, 480, 8);
  Eigen::Isometry3d T_cur_prev;
};

// prev: camera at the origin; cur: camera panned by `yaw` and moved by `c`, the patch by `patch`.
Pair make_pair(const Scene& s, double yaw, const Eigen::Vector3d& c, const cv::Point2d& patch) {
  Pair p;
  p.prev = test::render(s.planes({0, 0}), Eigen::Isometry3d::Identity());
  const Eigen::Isometry3d T_w_cur = pose(yaw, c);
  p.cur = test::render(s.planes(patch), T_w_cur);
  p.T_cur_prev = T_w_cur.inverse();
  return p;
}

DynamicInput input(const Pair& p, bool depth, const Detections* det = nullptr) {
  DynamicInput in;
  in.frame_index = 1;
  in.prev_gray = &p.prev.gray;
  in.gray = &p.cur.gray;
  in.keypoints = &p.kps;
  in.detections = det;
  if (depth) {
    in.depth = &p.cur.depth;
    in.K = test::test_K();
  }
  return in;
}

TEST(MotionCheck, PanWithParallaxCompensatedByReprojection) {
  const Scene s;
  const Pair p = make_pair(s, 1.5, {0.04, 0, 0}, {0, 0.05});
  for (const char* fit : {"ransac", "msac"}) {  // both camera-motion fits, no prediction given
    SCOPED_TRACE(fit);
    MotionCheckConfig cfg;
    cfg.mode = CullMode::kFlowOnly;
    cfg.ego_fit = fit;
    cfg.ego_fit_threshold_px = 0.7;  // msac only
    DynamicFeatureFilter f(cfg);
    const DynamicResult r = f.process(input(p, true));
    EXPECT_EQ(r.residual_used, "reprojection");
    const Shares sh = shares(r, p.cur.label);
    EXPECT_GT(sh.raw_flow_background, 5.0);  // the camera's own motion is large ...
    EXPECT_GT(sh.count[0], 50);
    EXPECT_GE(sh.count[2], 6);
    EXPECT_LE(sh.moving[0], 0.03);  // ... yet the wall and the board stay static
    EXPECT_LE(sh.moving[1], 0.03);
    EXPECT_GE(sh.moving[2], 0.8);  // and the patch moves
  }
}

TEST(MotionCheck, PanWithParallaxCompensatedByEpipolarDistance) {
  const Scene s;
  const Pair p = make_pair(s, 1.5, {0.04, 0, 0}, {0, 0.05});  // patch moves across the epipolar lines
  MotionCheckConfig cfg;
  cfg.mode = CullMode::kFlowOnly;
  DynamicFeatureFilter f(cfg);
  const DynamicResult r = f.process(input(p, false));
  EXPECT_EQ(r.residual_used, "epipolar");
  const Shares sh = shares(r, p.cur.label);
  EXPECT_GT(sh.raw_flow_background, 5.0);
  EXPECT_LE(sh.moving[0], 0.05);
  EXPECT_LE(sh.moving[1], 0.05);
  EXPECT_GE(sh.moving[2], 0.8);
}

TEST(MotionCheck, RotatingCameraUsesHomography) {
  Scene s;
  s.with_board = false;
  const Pair p = make_pair(s, 2.0, {0, 0, 0}, {0.04, 0.0});
  MotionCheckConfig cfg;
  cfg.mode = CullMode::kFlowOnly;
  DynamicFeatureFilter f(cfg);
  const DynamicResult r = f.process(input(p, false));
  EXPECT_EQ(r.residual_used, "homography");
  const Shares sh = shares(r, p.cur.label);
  EXPECT_GT(sh.raw_flow_background, 10.0);
  EXPECT_LE(sh.moving[0], 0.03);
  EXPECT_GE(sh.moving[2], 0.8);
}

struct KpShares {
  double dyn_patch = 0, dyn_outside = 0, dyn_wall_in_box = 0;
};

KpShares keypoint_shares(const Pair& p, const DynamicResult& r, const std::vector<cv::Rect2f>& boxes) {
  int np = 0, dp = 0, no = 0, dout = 0, nw = 0, dw = 0;
  for (std::size_t k = 0; k < p.kps.size(); ++k) {
    const cv::Point2f& pt = p.kps[k].pt;
    const int l = p.cur.label.at<uchar>(cvRound(pt.y), cvRound(pt.x));
    bool in_box = false;
    for (const auto& b : boxes) in_box = in_box || b.contains(pt);
    const bool d = r.keypoint_dynamic[k];
    if (l == 2) {
      ++np, dp += d;
    } else if (!in_box) {
      ++no, dout += d;
    } else if (l == 0) {
      ++nw, dw += d;
    }
  }
  return {np ? double(dp) / np : 0, no ? double(dout) / no : 0, nw ? double(dw) / nw : 0};
}

TEST(MotionCheck, MovingBoxCulledStaticBoxKeptBackgroundInBoxKept) {
  const Scene s;
  const Pair p = make_pair(s, 1.5, {0.04, 0, 0}, {0, 0.05});
  // A loose person box round the patch (wall behind it shows) and a person box on the static board.
  cv::Rect2f patch_box = test::label_box(p.cur.label, 2);
  patch_box = cv::Rect2f(patch_box.x - 30, patch_box.y - 30, patch_box.width + 60, patch_box.height + 60);
  const cv::Rect2f board_box = test::label_box(p.cur.label, 1);
  Detections det;
  det.frame_index = 1;
  det.items = {{patch_box, 0, 0.9f}, {board_box, 0, 0.8f}};
  MotionCheckConfig cfg;
  cfg.static_proof_frames = 0;  // one frame decides (the static-until-proven rule is tested below)
  DynamicFeatureFilter f{cfg};
  const DynamicResult r = f.process(input(p, true, &det));
  ASSERT_EQ(r.box_dynamic.size(), 2u);
  EXPECT_TRUE(r.box_dynamic[0]);
  EXPECT_FALSE(r.box_dynamic[1]);
  const KpShares k = keypoint_shares(p, r, {patch_box, board_box});
  EXPECT_GE(k.dyn_patch, 0.97);
  EXPECT_LE(k.dyn_outside, 0.02);
  EXPECT_LE(k.dyn_wall_in_box, 0.1);  // the wall 1 m behind the patch is depth-separated and kept
  EXPECT_EQ(r.culled,
            static_cast<int>(std::count(r.keypoint_dynamic.begin(), r.keypoint_dynamic.end(), true)));
}

// A camera-motion fit that fails (here: no depth for PnP, so a wrong predicted motion is kept) makes
// the whole static scene look like it moves. The motion check must notice that most of the points
// it fitted on moved and decide nothing by flow, rather than cull the background.
TEST(MotionCheck, WrongCameraMotionFitIsRejectedNotCulled) {
  const Scene s;
  Pair p = make_pair(s, 1.5, {0.04, 0, 0}, {0, 0.05});
  const cv::Mat label = p.cur.label.clone();
  p.cur.depth.setTo(0.f);  // no point for PnP: the prediction is all there is
  const cv::Rect2f patch_box = test::label_box(label, 2);
  Detections det;
  det.frame_index = 1;
  det.items = {{patch_box, 0, 0.9f}};
  MotionCheckConfig cfg;
  cfg.static_proof_frames = 0;
  DynamicInput in = input(p, true, &det);

  in.T_cur_prev_predicted = p.T_cur_prev;  // control: the right motion
  const DynamicResult right = DynamicFeatureFilter(cfg).process(in);
  EXPECT_FALSE(right.ego_motion_rejected);
  EXPECT_LE(keypoint_shares(p, right, {patch_box}).dyn_outside, 0.02);

  in.T_cur_prev_predicted = pose(-4.0, {-0.05, 0, 0}).inverse();  // panned the other way
  cfg.max_moving_share = 1.0;  // without the rule, the background is culled
  const DynamicResult unguarded = DynamicFeatureFilter(cfg).process(in);
  EXPECT_FALSE(unguarded.ego_motion_rejected);
  EXPECT_GE(keypoint_shares(p, unguarded, {patch_box}).dyn_outside, 0.3);

  cfg.max_moving_share = 0.5;
  const DynamicResult guarded = DynamicFeatureFilter(cfg).process(in);
  EXPECT_TRUE(guarded.ego_motion_rejected);
  const KpShares k = keypoint_shares(p, guarded, {patch_box});
  EXPECT_LE(k.dyn_outside, 0.02);  // no background culled
  ASSERT_EQ(guarded.box_dynamic.size(), 1u);
  EXPECT_TRUE(guarded.box_dynamic[0]);  // the person's class decides, as without flow
  EXPECT_GE(k.dyn_patch, 0.97);
}

TEST(MotionCheck, AblationModes) {
  const Scene s;
  const Pair p = make_pair(s, 1.5, {0.04, 0, 0}, {0, 0.05});
  const cv::Rect2f patch_box = test::label_box(p.cur.label, 2), board_box = test::label_box(p.cur.label, 1);
  Detections det;
  det.frame_index = 1;
  det.items = {{patch_box, 0, 0.9f}, {board_box, 0, 0.8f}};
  MotionCheckConfig cfg;
  cfg.mode = CullMode::kDetectorOnly;
  const DynamicResult d = DynamicFeatureFilter(cfg).process(input(p, true, &det));
  EXPECT_TRUE(d.flow_points.empty());  // no motion check at all
  EXPECT_TRUE(d.box_dynamic[0] && d.box_dynamic[1]);
  cfg.mode = CullMode::kFlowOnly;
  const DynamicResult fo = DynamicFeatureFilter(cfg).process(input(p, true, &det));
  EXPECT_TRUE(fo.boxes.empty());
  const KpShares k = keypoint_shares(p, fo, {});
  EXPECT_GE(k.dyn_patch, 0.7);
  EXPECT_LE(k.dyn_outside, 0.03);
  cfg.mode = CullMode::kOff;
  EXPECT_EQ(DynamicFeatureFilter(cfg).process(input(p, true, &det)).culled, 0);
}

// An unboxed mover culls the keypoints nearest to its points, but not the background beside it: a wall
// keypoint 1 m behind the moving patch is not the patch, even when a patch point is its nearest flow point.
TEST(MotionCheck, UnboxedMoverCullsNoDepthSeparatedBackground) {
  const Scene s;
  const Pair p = make_pair(s, 1.5, {0.04, 0, 0}, {0, 0.05});
  const auto label_at = [&](const cv::Point2f& q) {
    return p.cur.label.at<uchar>(cvRound(q.y), cvRound(q.x));
  };
  // Share culled of the wall keypoints whose nearest flow point (within the radius) lies on the patch.
  const auto wall_next_to_patch_culled = [&](const DynamicResult& r, double radius) {
    int n = 0, culled = 0;
    for (std::size_t k = 0; k < p.kps.size(); ++k) {
      if (label_at(p.kps[k].pt) != 0) continue;
      double best = radius * radius;
      int nearest = -1;
      for (std::size_t j = 0; j < r.flow_points.size(); ++j) {
        const cv::Point2f d = r.flow_points[j] - p.kps[k].pt;
        if (d.dot(d) < best) best = d.dot(d), nearest = static_cast<int>(j);
      }
      if (nearest < 0 || label_at(r.flow_points[static_cast<std::size_t>(nearest)]) != 2) continue;
      ++n, culled += r.keypoint_dynamic[k] ? 1 : 0;
    }
    EXPECT_GE(n, 10);
    return n > 0 ? static_cast<double>(culled) / n : 1.0;
  };
  MotionCheckConfig cfg;
  cfg.mode = CullMode::kFlowOnly;  // no boxes: the patch is an unboxed mover
  cfg.unboxed_depth_separated = false;
  const DynamicResult nearest_only = DynamicFeatureFilter(cfg).process(input(p, true));
  EXPECT_GE(wall_next_to_patch_culled(nearest_only, cfg.unboxed_radius_px), 0.5);  // the wall went too
  cfg.unboxed_depth_separated = true;
  const DynamicResult separated = DynamicFeatureFilter(cfg).process(input(p, true));
  EXPECT_LE(wall_next_to_patch_culled(separated, cfg.unboxed_radius_px), 0.05);
  EXPECT_GE(keypoint_shares(p, separated, {}).dyn_patch, 0.7);  // the patch itself is still culled
}

// A far wall beyond the sensor's range has no depth, so its points are judged by their epipolar distance
// under the camera motion fitted on the few near points; that motion can be a fraction of a degree off
// in rotation (here: the fit failed and a prediction 0.12 deg off in pitch is used), which moves the
// wall's points across their epipolar lines. With depthless_homography the wall's points follow the
// homography most depthless points follow and are not movers; the walking patch does not follow it.
TEST(MotionCheck, FarWallWithoutDepthIsNoMoverUnderASlightlyWrongMotion) {
  Scene s;
  s.with_board = false;
  Pair p = make_pair(s, 0.0, {0.01, 0, 0}, {0.05, 0});
  p.cur.depth.setTo(0.f);  // the wall and the patch: out of range
  MotionCheckConfig cfg;
  cfg.mode = CullMode::kFlowOnly;  // no boxes: the patch is an unboxed mover
  cfg.max_moving_share = 1.0;      // judge every frame (the rejection rule is tested on its own)
  DynamicInput in = input(p, true);
  Eigen::Isometry3d tilt = Eigen::Isometry3d::Identity();
  tilt.linear() = Eigen::AngleAxisd(0.12 * M_PI / 180, Eigen::Vector3d::UnitX()).toRotationMatrix();
  in.T_cur_prev_predicted = (pose(0.0, {0.01, 0, 0}) * tilt).inverse();

  cfg.depthless_homography = false;
  const KpShares off = keypoint_shares(p, DynamicFeatureFilter(cfg).process(in), {});
  EXPECT_GE(off.dyn_outside, 0.3);  // the wall is culled as a mover
  EXPECT_GE(off.dyn_patch, 0.7);

  cfg.depthless_homography = true;
  const KpShares on = keypoint_shares(p, DynamicFeatureFilter(cfg).process(in), {});
  EXPECT_LE(on.dyn_outside, 0.03);
  EXPECT_GE(on.dyn_patch, 0.7);  // the walking patch is still culled
}

TEST(MotionCheck, PausingPersonIsHeldDynamicThenReleased) {
  const Scene s;
  const cv::Point2d at[] = {{0, 0}, {0.05, 0}, {0.05, 0}, {0.05, 0}};  // moves once, then stands
  std::vector<Rendered> frames;
  for (const auto& o : at) frames.push_back(test::render(s.planes(o), Eigen::Isometry3d::Identity()));
  const auto kps = test::grid_keypoints(640, 480, 8);
  for (int hold : {10, 1}) {
    MotionCheckConfig cfg;
    cfg.dynamic_hold_frames = hold;
    cfg.static_proof_frames = 0;  // the hold alone
    DynamicFeatureFilter f(cfg);
    std::vector<bool> dyn;
    for (std::size_t i = 1; i < frames.size(); ++i) {
      Detections det;
      det.frame_index = i;
      det.items = {{test::label_box(frames[i].label, 2), 0, 0.9f}};
      dyn.push_back(f.process(sequence_input(frames, i, &kps, &det, false)).box_dynamic.at(0));
    }
    EXPECT_TRUE(dyn[0]);
    EXPECT_EQ(dyn[2], hold == 10) << "hold " << hold;  // frame 3: two frames after the last motion
  }
}

// A person standing still (the board, boxed as a person) next to a chair (boxed, class 56), static
// camera: the person stays dynamic until the motion check has seen it still static_proof_frames
// times in a row; the chair, not of a dynamic class, is static from the first check; kept keypoints
// in the boxes are suspect for the pose guard.
TEST(MotionCheck, StillPersonIsDynamicUntilProvenStatic) {
  const Scene s;
  const Rendered f = test::render(s.planes({0, 0}), Eigen::Isometry3d::Identity());
  const auto kps = test::grid_keypoints(640, 480, 8);
  const cv::Rect2f person = test::label_box(f.label, 1), chair = test::label_box(f.label, 2);
  for (int proof : {0, 4}) {
    MotionCheckConfig cfg;
    cfg.static_proof_frames = proof;
    cfg.still_people_fallback_keypoints = 100000;  // proven-still people are kept (tested below)
    DynamicFeatureFilter filter(cfg);
    for (std::size_t i = 1; i <= 6; ++i) {
      Detections det;
      det.frame_index = i;
      det.items = {{person, 0, 0.9f}, {chair, 56, 0.9f}};
      const DynamicResult r = filter.process(still_input(f, i, &kps, &det));
      ASSERT_EQ(r.box_dynamic.size(), 2u);
      EXPECT_EQ(r.box_dynamic[0], static_cast<int>(i) < proof) << "proof " << proof << " frame " << i;
      EXPECT_FALSE(r.box_dynamic[1]) << "frame " << i;
      int suspect_in_chair = 0, suspect_far = 0;
      for (std::size_t k = 0; k < kps.size(); ++k) {
        if (!r.keypoint_suspect[k]) continue;
        EXPECT_FALSE(r.keypoint_dynamic[k]);
        const cv::Point2f& p = kps[k].pt;
        if (chair.contains(p)) ++suspect_in_chair;
        const auto grown = [](const cv::Rect2f& b) {
          return cv::Rect2f(b.x - 10, b.y - 10, b.width + 20, b.height + 20);
        };
        const bool near_box = grown(person).contains(p) || grown(chair).contains(p);
        if (!near_box) ++suspect_far;
      }
      EXPECT_GT(suspect_in_chair, 50);
      EXPECT_EQ(suspect_far, 0);
    }
  }
}

// A person proven still is culled anyway while the rest of the image has enough keypoints; with only
// a few keypoints outside the person, its features are used (and marked suspect).
TEST(MotionCheck, ProvenStillPeopleAreCulledUnlessTheRestIsTooPoor) {
  const Scene s;
  const Rendered f = test::render(s.planes({0, 0}), Eigen::Isometry3d::Identity());
  const cv::Rect2f person = test::label_box(f.label, 1);
  const auto all = test::grid_keypoints(640, 480, 8);
  // The person's keypoints and every 50th of the others (~80, spread over the image so the camera
  // motion can still be fitted): fewer than still_people_fallback_keypoints (150) remain without it.
  std::vector<cv::KeyPoint> poor;
  for (std::size_t k = 0; k < all.size(); ++k) {
    if (person.contains(all[k].pt) || k % 50 == 0) poor.push_back(all[k]);
  }
  for (const std::vector<cv::KeyPoint>* kps : {&all, static_cast<const std::vector<cv::KeyPoint>*>(&poor)}) {
    MotionCheckConfig cfg;
    cfg.static_proof_frames = 2;
    const DynamicResult r =
        test::still_person_frames(cfg, f, person, *kps, 4);  // proven still from frame 2 on
    int person_kept = 0, person_total = 0;
    for (std::size_t k = 0; k < kps->size(); ++k) {
      if (!person.contains((*kps)[k].pt)) continue;
      ++person_total;
      person_kept += r.keypoint_dynamic[k] ? 0 : 1;
      if (!r.keypoint_dynamic[k]) {
        EXPECT_TRUE(r.keypoint_suspect[k]);
      }
    }
    ASSERT_GT(person_total, 100);
    const bool rich = kps == &all;
    EXPECT_EQ(r.still_people_released, !rich);
    EXPECT_EQ(r.box_dynamic.at(0), rich);
    if (rich) {
      EXPECT_EQ(person_kept, 0);
    } else {
      EXPECT_EQ(person_kept, person_total);
    }
  }
}

// A loose box round the moving patch takes in far more wall (1 m behind) than patch: counted over
// all its points the box looks still; counted at the object's depth it moves.
TEST(MotionCheck, LooseBoxVotesAtObjectDepth) {
  Scene s;
  s.with_board = false;
  const Pair p = make_pair(s, 0.0, {0, 0, 0}, {0.05, 0});
  const cv::Rect2f patch = test::label_box(p.cur.label, 2);
  const float m = 140.f;
  const cv::Rect2f loose(patch.x - m, patch.y - m, patch.width + 2 * m, patch.height + 2 * m);
  Detections det;
  det.frame_index = 1;
  det.items = {{loose, 0, 0.9f}};
  for (bool at_depth : {false, true}) {
    MotionCheckConfig cfg;
    cfg.static_proof_frames = 0;  // the vote alone decides
    cfg.ratio_at_object_depth = at_depth;
    const DynamicResult r = DynamicFeatureFilter(cfg).process(input(p, true, &det));
    // The premise: few of the box's tracked points are on the patch.
    int in_box = 0, on_patch = 0;
    for (std::size_t i = 0; i < r.flow_points.size(); ++i) {
      if (!loose.contains(r.flow_points[i])) continue;
      ++in_box;
      on_patch +=
          p.cur.label.at<uchar>(cv::Point(cvRound(r.flow_points[i].x), cvRound(r.flow_points[i].y))) == 2;
    }
    ASSERT_LT(on_patch, cfg.moving_ratio_threshold * in_box);
    ASSERT_EQ(r.box_dynamic.size(), 1u);
    EXPECT_EQ(r.box_dynamic[0], at_depth);
  }
}

TEST(MotionCheck, FirstFrameTrustsAlwaysDynamicClasses) {
  const Scene s;
  const Rendered f0 = test::render(s.planes({0, 0}), Eigen::Isometry3d::Identity());
  const auto kps = test::grid_keypoints(640, 480, 8);
  Detections det;
  det.items = {{test::label_box(f0.label, 2), 0, 0.9f}, {test::label_box(f0.label, 1), 56 /* chair */, 0.9f}};
  DynamicInput in;
  in.gray = &f0.gray;
  in.keypoints = &kps;
  in.detections = &det;
  const DynamicResult r = DynamicFeatureFilter{MotionCheckConfig{}}.process(in);
  EXPECT_TRUE(r.box_dynamic[0]);
  EXPECT_FALSE(r.box_dynamic[1]);
  EXPECT_GT(r.culled, 100);
  EXPECT_EQ(r.residual_used, "none");
}

TEST(MotionCheck, ConfigAndInputErrors) {
  const auto r =
      ConfigReader::from_string("mode: flow_only\nepsilon_epipolar_px: 1.5\nlk_window: 15\n", "m.yaml");
  const MotionCheckConfig c = MotionCheckConfig::from_yaml(r);
  r.finish();
  EXPECT_EQ(c.mode, CullMode::kFlowOnly);
  EXPECT_DOUBLE_EQ(c.epsilon_epipolar_px, 1.5);
  EXPECT_EQ(c.lk_window, 15);  // the file overrides the default
  EXPECT_THROW(MotionCheckConfig::from_yaml(ConfigReader::from_string("mode: magic\n", "m.yaml")),
               ConfigError);
  EXPECT_THROW(
      MotionCheckConfig::from_yaml(ConfigReader::from_string("moving_ratio_threshold: 2\n", "m.yaml")),
      ConfigError);
  EXPECT_THROW(MotionCheckConfig::from_yaml(ConfigReader::from_string("ego_fit: lmeds\n", "m.yaml")),
               ConfigError);
  const MotionCheckConfig msac = MotionCheckConfig::from_yaml(
      ConfigReader::from_string("ego_fit: msac\nego_fit_threshold_px: 0.7\n", "m.yaml"));
  EXPECT_EQ(msac.ego_fit, "msac");
  EXPECT_DOUBLE_EQ(msac.ego_fit_threshold_px, 0.7);
  MotionCheckConfig bad;
  bad.always_dynamic_classes = {"unicorn"};
  EXPECT_THROW(DynamicFeatureFilter{bad}, ConfigError);
  DynamicFeatureFilter f{MotionCheckConfig{}};
  const cv::Mat a(480, 640, CV_8U, cv::Scalar(0)), b(240, 320, CV_8U, cv::Scalar(0));
  DynamicInput in;
  in.prev_gray = &b;
  in.gray = &a;
  EXPECT_THROW(f.process(in), Error);
  in.gray = nullptr;
  EXPECT_THROW(f.process(in), Error);
}

}  // namespace
}  // namespace sp::dyn

namespace sp::dyn {
namespace {

// The cached pyramid of the previous call must give the same flow as building it afresh.
TEST(MotionCheck, CachedPyramidGivesTheSameFlow) {
  const Scene s;
  std::vector<Rendered> f;
  for (int i = 0; i < 3; ++i)
    f.push_back(test::render(s.planes({0.03 * i, 0.01 * i}), pose(0.5 * i, {0.01 * i, 0, 0})));
  const auto kps = test::grid_keypoints(640, 480, 8);
  const auto run = [&](DynamicFeatureFilter& filter, std::size_t i, const cv::Mat& prev, const cv::Mat& cur) {
    DynamicInput in;
    in.frame_index = i;
    in.prev_gray = &prev;
    in.gray = &cur;
    in.keypoints = &kps;
    return filter.process(in);
  };
  DynamicFeatureFilter a{MotionCheckConfig{}}, b{MotionCheckConfig{}};
  run(a, 1, f[0].gray, f[1].gray);
  const cv::Mat prev_copy = f[1].gray.clone();  // another buffer, same content: cache hit
  const DynamicResult ra = run(a, 2, prev_copy, f[2].gray);
  const DynamicResult rb = run(b, 2, f[1].gray, f[2].gray);  // fresh filter: no cache
  ASSERT_EQ(ra.flow_points.size(), rb.flow_points.size());
  ASSERT_GT(ra.flow_points.size(), 100u);
  for (std::size_t i = 0; i < ra.flow_points.size(); ++i) {
    EXPECT_FLOAT_EQ(ra.flow_prev[i].x, rb.flow_prev[i].x);
    EXPECT_FLOAT_EQ(ra.flow_prev[i].y, rb.flow_prev[i].y);
  }
  cv::Mat changed = f[1].gray.clone();
  changed.at<uchar>(0, 0) ^= 1;  // different content: rebuilt, still close
  const DynamicResult rc = run(a, 3, changed, f[2].gray);
  EXPECT_GT(rc.flow_points.size(), 100u);
}

}  // namespace
}  // namespace sp::dyn
