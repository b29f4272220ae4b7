#pragma once
// A tiny ray-cast scene for motion-check tests: fronto-parallel textured planes (a wall, a static
// board, a moving patch) seen by a pinhole camera, rendered with exact depth and labels.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

namespace sp::dyn::test {

struct Plane {
  double z;                // world depth of the plane
  cv::Rect2d extent;       // world x/y extent (empty = infinite)
  double px_per_m;         // texture resolution
  const cv::Mat* texture;  // CV_8U
  int label;
};

struct Rendered {
  cv::Mat gray;   // CV_8U
  cv::Mat depth;  // CV_32F, camera z in metres
  cv::Mat label;  // CV_8U, plane label
};

inline Eigen::Matrix3d test_K() {
  Eigen::Matrix3d K;
  K << 535.4, 0, 320.1, 0, 539.2, 247.6, 0, 0, 1;
  return K;
}

// Blurred noise at several scales, so LK has structure on every pyramid level (like real images).
inline cv::Mat make_texture(int seed, int size = 512) {
  cv::RNG rng(static_cast<uint64_t>(seed));
  cv::Mat sum(size, size, CV_32F, cv::Scalar(0));
  for (double sigma : {1.5, 4.0, 12.0}) {
    cv::Mat n(size, size, CV_32F);
    rng.fill(n, cv::RNG::UNIFORM, 0.0, 1.0);
    cv::GaussianBlur(n, n, cv::Size(0, 0), sigma, sigma, cv::BORDER_REFLECT);
    cv::normalize(n, n, 0, 1, cv::NORM_MINMAX);
    sum += n;
  }
  cv::Mat t;
  cv::normalize(sum, sum, 0, 255, cv::NORM_MINMAX);
  sum.convertTo(t, CV_8U);
  return t;
}

// T_world_cam: camera pose in the world (x right, y down, z forward).
inline Rendered render(const std::vector<Plane>& planes, const Eigen::Isometry3d& T_world_cam, int w = 640,
                       int h = 480) {
  const Eigen::Matrix3d Ki = test_K().inverse();
  const Eigen::Matrix3d R = T_world_cam.linear();
  const Eigen::Vector3d c = T_world_cam.translation();
  Rendered out;
  out.gray = cv::Mat(h, w, CV_8U, cv::Scalar(0));
  out.depth = cv::Mat(h, w, CV_32F, cv::Scalar(0));
  out.label = cv::Mat(h, w, CV_8U, cv::Scalar(255));
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const Eigen::Vector3d rc = Ki * Eigen::Vector3d(u, v, 1.0);
      const Eigen::Vector3d d = R * rc;
      double best = 1e9;
      const Plane* hit = nullptr;
      Eigen::Vector3d p;
      for (const Plane& pl : planes) {
        const double s = (pl.z - c.z()) / d.z();
        if (s <= 0 || s >= best) continue;
        const Eigen::Vector3d q = c + s * d;
        if (pl.extent.area() > 0 && !pl.extent.contains(cv::Point2d(q.x(), q.y()))) continue;
        best = s, hit = &pl, p = q;
      }
      if (hit == nullptr) continue;
      // Texture coordinates relative to the plane's corner, so a moving plane carries its texture.
      const double tx = (p.x() - hit->extent.x) * hit->px_per_m, ty = (p.y() - hit->extent.y) * hit->px_per_m;
      const cv::Mat& t = *hit->texture;
      const int x0 = static_cast<int>(std::floor(tx)), y0 = static_cast<int>(std::floor(ty));
      const double fx = tx - x0, fy = ty - y0;
      const auto at = [&](int x, int y) {
        x = ((x % t.cols) + t.cols) % t.cols;
        y = ((y % t.rows) + t.rows) % t.rows;
        return static_cast<double>(t.at<uchar>(y, x));
      };
      const double val = (1 - fx) * (1 - fy) * at(x0, y0) + fx * (1 - fy) * at(x0 + 1, y0) +
                         (1 - fx) * fy * at(x0, y0 + 1) + fx * fy * at(x0 + 1, y0 + 1);
      out.gray.at<uchar>(v, u) = cv::saturate_cast<uchar>(val);
      out.depth.at<float>(v, u) = static_cast<float>(best * rc.z());
      out.label.at<uchar>(v, u) = static_cast<uchar>(hit->label);
    }
  }
  return out;
}

// Image bounding box of the pixels with a label.
inline cv::Rect2f label_box(const cv::Mat& label, int l) {
  cv::Mat m = label == l;
  const cv::Rect r = cv::boundingRect(m);
  return {static_cast<float>(r.x), static_cast<float>(r.y), static_cast<float>(r.width),
          static_cast<float>(r.height)};
}

inline std::vector<cv::KeyPoint> grid_keypoints(int w, int h, int step) {
  std::vector<cv::KeyPoint> k;
  for (int y = step / 2; y < h; y += step) {
    for (int x = step / 2; x < w; x += step) k.emplace_back(cv::Point2f(x, y), 7.f, -1.f, 1.f);
  }
  return k;
}

}  // namespace sp::dyn::test
