#pragma once
// ORB feature extraction in the style of ORB-SLAM: scale pyramid, FAST on a cell grid with a
// fallback threshold, quadtree distribution for spatially uniform keypoints, intensity-centroid
// orientation and steered 256-bit BRIEF descriptors on a blurred level image.
#include <array>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "stillpoint/common/config_reader.hpp"
#include "stillpoint/features/orb_pattern.hpp"
#include "stillpoint/features/quadtree.hpp"

namespace sp::feat {

struct OrbConfig {
  int n_features = 1000;       // keypoints per frame (all levels together) [count]
  double scale_factor = 1.2;   // scale ratio between consecutive pyramid levels [-]
  int n_levels = 8;            // pyramid levels [count]
  int fast_threshold = 20;     // FAST intensity threshold tried first in each cell [grey levels]
  int fast_min_threshold = 7;  // FAST threshold used in cells where the first finds nothing [grey levels]
  // Extract pyramid levels concurrently with cv::parallel_for_; output is identical either way.
  bool parallel_levels = false;
  // Descriptor sampling pattern: "gaussian" (OrbPattern::generate(), what data/vocab was trained
  // on) or "decorrelated" (OrbPattern::decorrelated(); needs a vocabulary trained on it).
  std::string pattern = "gaussian";

  static OrbConfig from_yaml(const sp::ConfigReader& r);
  // Throws sp::Error when a value is out of range (for configs built in code).
  void validate() const;
};

// Not thread-safe: extract() reuses per-level buffers. Use one extractor per thread.
class OrbExtractor {
 public:
  static constexpr int kPatchSize = 31;  // descriptor / orientation patch diameter [px]
  static constexpr int kHalfPatch = 15;  // orientation patch radius [px]
  static constexpr int kEdge = 19;       // padding of pyramid levels [px]
  static constexpr int kCellSize = 30;   // FAST detection cell size [px]

  explicit OrbExtractor(const OrbConfig& config);
  // With an explicit sampling pattern (config.pattern is then ignored).
  OrbExtractor(const OrbConfig& config, const OrbPattern& pattern);

  // gray: CV_8UC1 image. mask (optional): CV_8UC1 of the same size, 0 = do not detect there.
  // keypoints in level-0 pixels, octave = level, angle in degrees [0, 360), size = 31 * scale.
  // descriptors: N x 32 CV_8U, row i belongs to keypoints[i]. Output is deterministic.
  void extract(const cv::Mat& gray, std::vector<cv::KeyPoint>& keypoints, cv::Mat& descriptors,
               const cv::Mat& mask = cv::Mat());
  struct AgainOptions {
    int max_keypoints = 0;  // budget of the new selection; 0 = n_features
    // Select among the corners the last extract() found (cheap: no FAST, no blur) rather than
    // running FAST again under the mask.
    bool reuse_detections = true;
  };
  // Detection again on the pyramid of the last extract() call (not rebuilt), only where mask != 0:
  // the keypoint budget goes to the unmasked area. Throws when extract() was not called.
  void extract_again(const cv::Mat& mask, std::vector<cv::KeyPoint>& keypoints, cv::Mat& descriptors,
                     const AgainOptions& options);
  void extract_again(const cv::Mat& mask, std::vector<cv::KeyPoint>& keypoints, cv::Mat& descriptors) {
    extract_again(mask, keypoints, descriptors, AgainOptions{});
  }

  [[nodiscard]] int levels() const noexcept { return config_.n_levels; }
  [[nodiscard]] double scale_factor() const noexcept { return config_.scale_factor; }
  [[nodiscard]] const std::vector<double>& scale_factors() const noexcept { return scale_; }
  [[nodiscard]] const std::vector<double>& inv_scale_factors() const noexcept { return inv_scale_; }
  [[nodiscard]] const std::vector<double>& level_sigma2() const noexcept { return sigma2_; }
  [[nodiscard]] const std::vector<double>& inv_level_sigma2() const noexcept { return inv_sigma2_; }
  // Target keypoint count of each level (geometric in the inverse scale, summing to n_features).
  [[nodiscard]] const std::vector<int>& features_per_level() const noexcept { return per_level_; }
  // The pyramid of the last extract() call (level images without padding; views into buffers).
  [[nodiscard]] cv::Mat level_image(int level) const;
  [[nodiscard]] const OrbConfig& config() const noexcept { return config_; }
  [[nodiscard]] const OrbPattern& pattern() const noexcept { return pattern_; }

 private:
  void build_pyramid(const cv::Mat& gray);
  [[nodiscard]] bool level_usable(std::size_t level, int quota) const;
  // Detection and description of one level with `quota` keypoints.
  void process_level(int level, const cv::Mat& mask, int quota);
  // FAST corners of one level (outside the mask) into its scratch `found`.
  void detect_level(int level, const cv::Mat& mask);
  // Selects `quota` of the candidates, orients and describes them (blur: the level's blurred copy
  // is rebuilt first).
  void describe_level(int level, const std::vector<cv::KeyPoint>& candidates, int quota, bool blur);
  template <typename F>
  void for_each_level(F&& work);
  void detect_and_describe(const cv::Mat& mask, std::vector<cv::KeyPoint>& keypoints, cv::Mat& descriptors);
  void collect(std::vector<cv::KeyPoint>& keypoints, cv::Mat& descriptors) const;

  OrbConfig config_;
  std::vector<double> scale_, inv_scale_, sigma2_, inv_sigma2_;
  std::vector<int> per_level_;
  std::vector<int> umax_;  // half-width of each row of the circular orientation patch
  OrbPattern pattern_;
  std::array<float, 2 * OrbPattern::kPairs> pattern_x_{}, pattern_y_{};  // the pattern as floats

  // Per-level buffers kept between calls (padded level image, blurred copy, results).
  std::vector<cv::Mat> padded_;
  std::vector<cv::Mat> blurred_;
  std::vector<cv::Size> level_size_;
  std::vector<std::vector<cv::KeyPoint>> level_kps_;
  std::vector<cv::Mat> level_desc_;
  struct LevelScratch {
    std::vector<cv::KeyPoint> found, cell_found;
    std::vector<cv::KeyPoint> unmasked;  // extract_again's candidates among `found`
    std::vector<int> cell_count;
    QuadtreeScratch quadtree;
  };
  std::vector<LevelScratch> scratch_;
};

}  // namespace sp::feat
