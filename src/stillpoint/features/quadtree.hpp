#pragma once
// Spatially uniform selection of keypoints (the ORB-SLAM "octree" idea): split the image region
// like a quadtree until there are about as many non-empty leaves as wanted keypoints, then keep the
// strongest keypoint of each leaf.
#include <opencv2/core/types.hpp>
#include <vector>

namespace sp::feat {

// Reusable buffers, so that repeated calls do not allocate.
struct QuadtreeScratch {
  struct Node {
    float x0, y0, x1, y1;  // bounds [x0, x1) x [y0, y1)
    int begin, end;        // range in `order`
  };
  std::vector<int> order;
  std::vector<Node> nodes, next;
  std::vector<int> picked;
};

// Selects at most `target` keypoints of `kps` lying in [x0, x1) x [y0, y1) and writes them to `out`
// (cleared first) sorted by decreasing response. Deterministic: ties are broken by position.
void distribute_quadtree(const std::vector<cv::KeyPoint>& kps, int target, float x0, float y0, float x1,
                         float y1, std::vector<cv::KeyPoint>& out, QuadtreeScratch& scratch);

}  // namespace sp::feat
