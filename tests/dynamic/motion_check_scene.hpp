// Rendered scenes and frame inputs shared by the motion-check tests: a wall, a patch (the walking
// person) and a board, seen by a still camera.
#pragma once

#include <vector>

#include "stillpoint/dynamic/dynamic_filter.hpp"
#include "synthetic_scene.hpp"

namespace sp::dyn::test {

struct Scene {
  cv::Mat wall_tex = test::make_texture(1), board_tex = test::make_texture(2),
          patch_tex = test::make_texture(3);
  bool with_board = true;
  std::vector<Plane> planes(const cv::Point2d& patch_offset) const {
    std::vector<Plane> p = {
        {3.0, cv::Rect2d(), 200, &wall_tex, 0},
        {2.0, cv::Rect2d(0.1 + patch_offset.x, -0.2 + patch_offset.y, 0.4, 0.4), 300, &patch_tex, 2}};
    if (with_board) p.push_back({1.5, cv::Rect2d(-0.7, -0.3, 0.6, 0.6), 400, &board_tex, 1});
    return p;
  }
};

// n frames of a still camera, the patch (a walking person) moved sideways by step_m per frame.
inline std::vector<Rendered> walking_patch_frames(const Scene& s, int n, double step_m) {
  std::vector<Rendered> frames;
  for (int i = 0; i < n; ++i)
    frames.push_back(test::render(s.planes({step_m * i, 0}), Eigen::Isometry3d::Identity()));
  return frames;
}

// Feeds frames 1.. to a default filter, each with the same (stale) detections; the last result.
inline DynamicResult run_frames(const std::vector<Rendered>& frames, const std::vector<cv::KeyPoint>& kps,
                                const Detections& det) {
  DynamicFeatureFilter f{MotionCheckConfig{}};
  DynamicResult r;
  for (std::size_t i = 1; i < frames.size(); ++i) {
    DynamicInput in;
    in.frame_index = i;
    in.prev_gray = &frames[i - 1].gray;
    in.gray = &frames[i].gray;
    in.keypoints = &kps;
    in.detections = &det;
    r = f.process(in);
  }
  return r;
}

// Frame i of a rendered sequence (previous image i - 1), with its depth and K when `depth`.
inline DynamicInput sequence_input(const std::vector<Rendered>& frames, std::size_t i,
                                   const std::vector<cv::KeyPoint>* kps, const Detections* det, bool depth) {
  DynamicInput in;
  in.frame_index = i;
  in.prev_gray = &frames[i - 1].gray;
  in.gray = &frames[i].gray;
  in.keypoints = kps;
  in.detections = det;
  if (depth) {
    in.depth = &frames[i].depth;
    in.K = test::test_K();
  }
  return in;
}

// Frame i of a static camera watching a still scene: the same image as previous and current frame.
inline DynamicInput still_input(const Rendered& f, std::size_t i, const std::vector<cv::KeyPoint>* kps,
                                const Detections* det) {
  DynamicInput in;
  in.frame_index = i;
  in.prev_gray = &f.gray;
  in.gray = &f.gray;
  in.depth = &f.depth;
  in.K = test::test_K();
  in.keypoints = kps;
  in.detections = det;
  return in;
}

// Keypoints inside `r`: how many, and how many of them `flag` marks.
struct InRect {
  int total = 0, flagged = 0;
};
inline InRect count_in(const cv::Rect2f& r, const std::vector<cv::KeyPoint>& kps,
                       const std::vector<bool>& flag) {
  InRect c;
  for (std::size_t k = 0; k < kps.size(); ++k) {
    if (!r.contains(kps[k].pt)) continue;
    ++c.total;
    c.flagged += flag[k] ? 1 : 0;
  }
  return c;
}

// A still camera watching a still person (box `person`, detected in every frame) over frames 1..n of
// the same image, with static_proof_frames as in `cfg`; the last frame's result.
inline DynamicResult still_person_frames(const MotionCheckConfig& cfg, const Rendered& f,
                                         const cv::Rect2f& person, const std::vector<cv::KeyPoint>& kps,
                                         std::size_t n) {
  DynamicFeatureFilter filter(cfg);
  DynamicResult r;
  for (std::size_t i = 1; i <= n; ++i) {
    Detections det;
    det.frame_index = i;
    det.items = {{person, 0, 0.9f}};
    r = filter.process(still_input(f, i, &kps, &det));
  }
  return r;
}

}  // namespace sp::dyn::test
