#pragma once
// New map points from two keyframes (ORB-SLAM's CreateNewMapPoints, RGB-D case). Features without a
// depth reading (a third to a half of ORB corners sit on depth edges and holes) and far features never
// become points at keyframe creation; here they are matched between a new keyframe and a neighbour
// along the epipolar line and triangulated, or taken from whichever view's depth gives the larger
// parallax. Works on copies of keyframe data, so it runs without the map lock.
#include <Eigen/Core>
#include <vector>

#include "stillpoint/common/config_reader.hpp"
#include "stillpoint/geometry/camera.hpp"
#include "stillpoint/geometry/lie.hpp"
#include "stillpoint/map/feature_set.hpp"

namespace sp::mapping {

struct TriangulationConfig {
  bool enabled = true;
  std::size_t neighbours = 10;       // best covisible keyframes paired with the new one (ORB-SLAM RGB-D: 10)
  int max_descriptor_distance = 50;  // Hamming, ORB-SLAM's TH_LOW
  double min_parallax_cos = 0.9998;  // rays closer than this (about 1.1 deg) are not triangulated
  // A match where neither feature has depth must be distinct along its epipolar band: best Hamming
  // distance <= this share of the second best, or of max_descriptor_distance when that is lower
  // (Lowe's ratio; 1: off). Nothing else checks such a pair: any two features on the epipolar line
  // triangulate to a point that reprojects onto both. 0.5 since session 29 (0.7 until session 28, then
  // 0.6: a brick wall beyond the sensor's range held the pose; docs/tracking_precision.md).
  double mono_match_ratio = 0.5;
  static TriangulationConfig from_yaml(const ConfigReader& r);
};

// What the triangulator needs of one keyframe.
struct TriangulationView {
  geo::SE3 T_cw;
  const map::FeatureSet* features = nullptr;
  std::vector<bool> free;  // per feature: true when it has no map point yet
};

struct TriangulatedPoint {
  Eigen::Vector3d position;
  int feature1 = -1;  // index in the first view
  int feature2 = -1;  // index in the second view
};

class PointTriangulator {
 public:
  PointTriangulator(TriangulationConfig config, geo::CameraIntrinsics camera, double bf,
                    map::ScalePyramid pyramid);

  // New points seen by free features of both views; each feature is used at most once.
  [[nodiscard]] std::vector<TriangulatedPoint> triangulate(const TriangulationView& v1,
                                                           const TriangulationView& v2) const;

  [[nodiscard]] const TriangulationConfig& config() const { return config_; }

 private:
  struct Match {
    int i1, i2, distance;
  };
  [[nodiscard]] std::vector<Match> match_epipolar(const TriangulationView& v1,
                                                  const TriangulationView& v2) const;
  [[nodiscard]] bool reprojects(const geo::SE3& T_cw, const map::FeatureSet& f, int i,
                                const Eigen::Vector3d& p_w, double* distance) const;

  TriangulationConfig config_;
  geo::CameraIntrinsics camera_;
  double bf_;
  map::ScalePyramid pyramid_;
};

}  // namespace sp::mapping
