#include "stillpoint/features/orb_extractor.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <opencv2/core/utility.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "stillpoint/common/error.hpp"
#include "stillpoint/features/quadtree.hpp"

namespace sp::feat {

OrbConfig OrbConfig::from_yaml(const sp::ConfigReader& r) {
  OrbConfig c;
  r.read("n_features", c.n_features, 1, 100000);
  r.read("scale_factor", c.scale_factor, 1.01, 4.0);
  r.read("n_levels", c.n_levels, 1, 20);
  r.read("fast_threshold", c.fast_threshold, 1, 254);
  r.read("fast_min_threshold", c.fast_min_threshold, 1, 254);
  r.read("parallel_levels", c.parallel_levels);
  r.read_choice("pattern", c.pattern, {"gaussian", "decorrelated"});
  if (c.fast_min_threshold > c.fast_threshold) {
    r.fail("fast_min_threshold", "must not exceed fast_threshold (" + std::to_string(c.fast_threshold) + ")");
  }
  return c;
}

void OrbConfig::validate() const {
  const auto bad = [](const std::string& what) { throw sp::Error("OrbConfig: " + what); };
  if (n_features < 1 || n_features > 100000) bad("n_features out of range [1, 100000]");
  if (!(scale_factor >= 1.01 && scale_factor <= 4.0)) bad("scale_factor out of range [1.01, 4]");
  if (n_levels < 1 || n_levels > 20) bad("n_levels out of range [1, 20]");
  if (fast_threshold < 1 || fast_threshold > 254) bad("fast_threshold out of range [1, 254]");
  if (fast_min_threshold < 1 || fast_min_threshold > fast_threshold) {
    bad("fast_min_threshold must be in [1, fast_threshold]");
  }
  if (pattern != "gaussian" && pattern != "decorrelated") bad("pattern must be gaussian or decorrelated");
}

namespace {

// Fills the kEdge-wide frame of `padded` by mirroring the inner image (BORDER_REFLECT_101).
void fill_reflect_border(cv::Mat& padded, int e) {
  const int w = padded.cols - 2 * e, h = padded.rows - 2 * e;
  for (int y = e; y < e + h; ++y) {
    std::uint8_t* row = padded.ptr<std::uint8_t>(y);
    for (int k = 1; k <= e; ++k) {
      row[e - k] = row[e + std::min(k, w - 1)];
      row[e + w - 1 + k] = row[e + w - 1 - std::min(k, w - 1)];
    }
  }
  for (int k = 1; k <= e; ++k) {
    std::memcpy(padded.ptr(e - k), padded.ptr(e + std::min(k, h - 1)), static_cast<std::size_t>(padded.cols));
    std::memcpy(padded.ptr(e + h - 1 + k), padded.ptr(e + h - 1 - std::min(k, h - 1)),
                static_cast<std::size_t>(padded.cols));
  }
}

// Intensity-centroid orientation over the disc described by umax; `c` points at the keypoint.
float ic_angle(const std::uint8_t* c, int step, const std::vector<int>& umax) {
  const int r = static_cast<int>(umax.size()) - 1;
  int m01 = 0, m10 = 0;
  for (int u = -r; u <= r; ++u) m10 += u * c[u];
  for (int v = 1; v <= r; ++v) {
    const std::uint8_t* below = c + v * step;
    const std::uint8_t* above = c - v * step;
    const int d = umax[static_cast<std::size_t>(v)];
    int v_sum = 0;
    for (int u = -d; u <= d; ++u) {
      const int p = below[u], m = above[u];
      v_sum += p - m;
      m10 += u * (p + m);
    }
    m01 += v * v_sum;
  }
  return cv::fastAtan2(static_cast<float>(m01), static_cast<float>(m10));
}

// Steered BRIEF: pattern rotated by the keypoint angle, pixel offsets rounded to nearest (ties to
// even, as cvRound). px/py: the pattern as floats, 2 * kPairs entries each.
void steered_brief(const std::uint8_t* c, int step, float angle_deg, const float* px, const float* py,
                   std::uint8_t* desc) {
  constexpr int kPoints = 2 * OrbPattern::kPairs;
  const float a = angle_deg * static_cast<float>(CV_PI / 180.0);
  const float ca = std::cos(a), sa = std::sin(a);
  alignas(16) int off[kPoints];
#if defined(__SSE2__)
  // Four points at a time; _mm_cvtps_epi32 rounds like cvRound and the sums stay exact in float.
  const __m128 vca = _mm_set1_ps(ca), vsa = _mm_set1_ps(sa), vstep = _mm_set1_ps(static_cast<float>(step));
  for (int i = 0; i < kPoints; i += 4) {
    const __m128 x = _mm_loadu_ps(px + i), y = _mm_loadu_ps(py + i);
    const __m128 rx = _mm_cvtepi32_ps(_mm_cvtps_epi32(_mm_sub_ps(_mm_mul_ps(x, vca), _mm_mul_ps(y, vsa))));
    const __m128 ry = _mm_cvtepi32_ps(_mm_cvtps_epi32(_mm_add_ps(_mm_mul_ps(x, vsa), _mm_mul_ps(y, vca))));
    _mm_store_si128(reinterpret_cast<__m128i*>(off + i),
                    _mm_cvtps_epi32(_mm_add_ps(_mm_mul_ps(ry, vstep), rx)));
  }
#else
  for (int i = 0; i < kPoints; ++i) {
    off[i] = cvRound(px[i] * sa + py[i] * ca) * step + cvRound(px[i] * ca - py[i] * sa);
  }
#endif
  for (int byte = 0; byte < OrbPattern::kPairs / 8; ++byte) {
    const int* o = off + byte * 16;
    int v = 0;
    for (int bit = 0; bit < 8; ++bit) v |= (c[o[2 * bit]] < c[o[2 * bit + 1]] ? 1 : 0) << bit;
    desc[byte] = static_cast<std::uint8_t>(v);
  }
}

}  // namespace

OrbExtractor::OrbExtractor(const OrbConfig& config)
    : OrbExtractor(config,
                   config.pattern == "decorrelated" ? OrbPattern::decorrelated() : OrbPattern::generate()) {}

OrbExtractor::OrbExtractor(const OrbConfig& config, const OrbPattern& pattern)
    : config_(config), pattern_(pattern) {
  config_.validate();
  const auto L = static_cast<std::size_t>(config_.n_levels);
  scale_.resize(L);
  inv_scale_.resize(L);
  sigma2_.resize(L);
  inv_sigma2_.resize(L);
  scale_[0] = 1.0;
  for (std::size_t i = 1; i < L; ++i) scale_[i] = scale_[i - 1] * config_.scale_factor;
  for (std::size_t i = 0; i < L; ++i) {
    inv_scale_[i] = 1.0 / scale_[i];
    sigma2_[i] = scale_[i] * scale_[i];
    inv_sigma2_[i] = 1.0 / sigma2_[i];
  }
  // Features per level in proportion to the level area's square root (geometric in 1/scale).
  per_level_.resize(L);
  const double f = 1.0 / config_.scale_factor;
  double desired = config_.n_features * (1.0 - f) / (1.0 - std::pow(f, config_.n_levels));
  int sum = 0;
  for (std::size_t i = 0; i + 1 < L; ++i) {
    per_level_[i] = static_cast<int>(std::lround(desired));
    sum += per_level_[i];
    desired *= f;
  }
  per_level_[L - 1] = std::max(config_.n_features - sum, 0);

  // Disc {u^2 + v^2 <= r^2 + r}: symmetric in u and v, so the centroid angle is rotation-consistent.
  umax_.resize(kHalfPatch + 1);
  for (int v = 0; v <= kHalfPatch; ++v) {
    int u = 0;
    while ((u + 1) * (u + 1) + v * v <= kHalfPatch * kHalfPatch + kHalfPatch) ++u;
    umax_[static_cast<std::size_t>(v)] = u;
  }
  padded_.resize(L);
  blurred_.resize(L);
  level_size_.resize(L);
  level_kps_.resize(L);
  level_desc_.resize(L);
  scratch_.resize(L);
  for (std::size_t i = 0; i < pattern_x_.size(); ++i) {
    pattern_x_[i] = pattern_.x[i];
    pattern_y_[i] = pattern_.y[i];
  }
}

cv::Mat OrbExtractor::level_image(int level) const {
  if (level < 0 || level >= config_.n_levels || padded_[static_cast<std::size_t>(level)].empty()) return {};
  const auto l = static_cast<std::size_t>(level);
  return padded_[l](cv::Rect(kEdge, kEdge, level_size_[l].width, level_size_[l].height));
}

void OrbExtractor::build_pyramid(const cv::Mat& gray) {
  for (std::size_t l = 0; l < static_cast<std::size_t>(config_.n_levels); ++l) {
    const cv::Size sz(static_cast<int>(std::lround(gray.cols * inv_scale_[l])),
                      static_cast<int>(std::lround(gray.rows * inv_scale_[l])));
    level_size_[l] = sz;
    padded_[l].create(sz.height + 2 * kEdge, sz.width + 2 * kEdge, CV_8UC1);
    if (sz.width < 1 || sz.height < 1) continue;
    cv::Mat inner = padded_[l](cv::Rect(kEdge, kEdge, sz.width, sz.height));
    if (l == 0) {
      gray.copyTo(inner);
    } else {
      const cv::Mat prev = level_image(static_cast<int>(l - 1));
      cv::resize(prev, inner, sz, 0, 0, cv::INTER_LINEAR);
    }
    fill_reflect_border(padded_[l], kEdge);
  }
}

bool OrbExtractor::level_usable(std::size_t l, int quota) const {
  // Below the patch size a level can hold no usable keypoint.
  return level_size_[l].width >= kPatchSize && level_size_[l].height >= kPatchSize && quota > 0;
}

namespace {
// Whether a level-`scale` position falls where the level-0 mask is 0 (an empty mask blocks nothing).
bool masked_out(const cv::Mat& mask, const cv::Point2f& p, float scale) {
  if (mask.empty()) return false;
  const int x = std::min(mask.cols - 1, static_cast<int>(std::lround(p.x * scale)));
  const int y = std::min(mask.rows - 1, static_cast<int>(std::lround(p.y * scale)));
  return mask.at<std::uint8_t>(y, x) == 0;
}
}  // namespace

void OrbExtractor::process_level(int level, const cv::Mat& mask, int quota) {
  const auto l = static_cast<std::size_t>(level);
  if (!level_usable(l, quota)) {
    level_kps_[l].clear();
    level_desc_[l].release();
    scratch_[l].found.clear();
    return;
  }
  detect_level(level, mask);
  describe_level(level, scratch_[l].found, quota, true);
}

void OrbExtractor::detect_level(int level, const cv::Mat& mask) {
  const auto l = static_cast<std::size_t>(level);
  const int w = level_size_[l].width, h = level_size_[l].height;
  const cv::Mat img = level_image(level);
  const float scale = static_cast<float>(scale_[l]);

  // FAST with the high threshold over the level; cells left empty are retried with the low one.
  LevelScratch& sc = scratch_[l];
  std::vector<cv::KeyPoint>& found = sc.found;
  cv::FAST(img, found, config_.fast_threshold, true);
  if (!mask.empty()) {
    std::erase_if(found, [&](const cv::KeyPoint& k) { return masked_out(mask, k.pt, scale); });
  }
  const int n_cols = std::max(1, w / kCellSize), n_rows = std::max(1, h / kCellSize);
  const int cell_w = (w + n_cols - 1) / n_cols, cell_h = (h + n_rows - 1) / n_rows;
  sc.cell_count.assign(static_cast<std::size_t>(n_cols * n_rows), 0);
  for (const cv::KeyPoint& k : found) {
    const int cx = std::min(n_cols - 1, static_cast<int>(k.pt.x) / cell_w);
    const int cy = std::min(n_rows - 1, static_cast<int>(k.pt.y) / cell_h);
    ++sc.cell_count[static_cast<std::size_t>(cy * n_cols + cx)];
  }
  if (config_.fast_min_threshold < config_.fast_threshold) {
    for (int cy = 0; cy < n_rows; ++cy) {
      const int* counts = sc.cell_count.data() + cy * n_cols;
      for (int cx = 0; cx < n_cols; ++cx) {
        if (counts[cx] > 0) continue;
        // One FAST call per horizontal run of empty cells: fewer calls and less overlap.
        int run_end = cx + 1;
        while (run_end < n_cols && counts[run_end] == 0) ++run_end;
        const int x0 = cx * cell_w, y0 = cy * cell_h;
        const int x1 = std::min(w, run_end * cell_w), y1 = std::min(h, y0 + cell_h);
        cx = run_end;
        // FAST skips a 3-pixel frame of its input: widen the window so the whole run is tested.
        const int wx0 = std::max(0, x0 - 3), wy0 = std::max(0, y0 - 3);
        const int wx1 = std::min(w, x1 + 3), wy1 = std::min(h, y1 + 3);
        if (wx1 - wx0 < 7 || wy1 - wy0 < 7) continue;
        cv::FAST(img(cv::Rect(wx0, wy0, wx1 - wx0, wy1 - wy0)), sc.cell_found, config_.fast_min_threshold,
                 true);
        for (cv::KeyPoint k : sc.cell_found) {
          k.pt.x += static_cast<float>(wx0);
          k.pt.y += static_cast<float>(wy0);
          if (k.pt.x < x0 || k.pt.x >= x1 || k.pt.y < y0 || k.pt.y >= y1 || masked_out(mask, k.pt, scale))
            continue;
          found.push_back(k);
        }
      }
    }
  }
}

void OrbExtractor::describe_level(int level, const std::vector<cv::KeyPoint>& candidates, int quota,
                                  bool blur) {
  const auto l = static_cast<std::size_t>(level);
  const int w = level_size_[l].width, h = level_size_[l].height;
  std::vector<cv::KeyPoint>& result = level_kps_[l];
  distribute_quadtree(candidates, quota, 0.f, 0.f, static_cast<float>(w), static_cast<float>(h), result,
                      scratch_[l].quadtree);
  const float scale = static_cast<float>(scale_[l]);

  // Orientation on the sharp level image, descriptors on the blurred one (both padded by kEdge).
  const int step = static_cast<int>(padded_[l].step);
  const std::uint8_t* origin = padded_[l].ptr<std::uint8_t>(kEdge) + kEdge;
  for (cv::KeyPoint& k : result) {
    const std::uint8_t* c = origin + cvRound(k.pt.y) * step + cvRound(k.pt.x);
    k.angle = ic_angle(c, step, umax_);
  }
  // Blur only the region the pattern reaches; as a non-isolated ROI the kernel still reads the
  // padding, so the values equal those of blurring the whole padded image.
  if (blur) {
    const int m = OrbPattern::kRadius + 1;
    blurred_[l].create(padded_[l].size(), CV_8UC1);
    const cv::Rect reach(kEdge - m, kEdge - m, w + 2 * m, h + 2 * m);
    cv::Mat blur_dst = blurred_[l](reach);
    cv::GaussianBlur(padded_[l](reach), blur_dst, cv::Size(7, 7), 2, 2, cv::BORDER_REFLECT_101);
  }
  level_desc_[l].create(static_cast<int>(result.size()), 32, CV_8UC1);
  const int bstep = static_cast<int>(blurred_[l].step);
  const std::uint8_t* borigin = blurred_[l].ptr<std::uint8_t>(kEdge) + kEdge;
  for (std::size_t i = 0; i < result.size(); ++i) {
    cv::KeyPoint& k = result[i];
    const std::uint8_t* c = borigin + cvRound(k.pt.y) * bstep + cvRound(k.pt.x);
    steered_brief(c, bstep, k.angle, pattern_x_.data(), pattern_y_.data(),
                  level_desc_[l].ptr<std::uint8_t>(static_cast<int>(i)));
    k.octave = level;
    k.size = static_cast<float>(kPatchSize * scale_[l]);
    k.pt *= scale;
  }
}

void OrbExtractor::extract(const cv::Mat& gray, std::vector<cv::KeyPoint>& keypoints, cv::Mat& descriptors,
                           const cv::Mat& mask) {
  if (gray.empty() || gray.type() != CV_8UC1)
    throw sp::Error("OrbExtractor::extract: image must be non-empty CV_8UC1");
  if (!mask.empty() && (mask.type() != CV_8UC1 || mask.size() != gray.size())) {
    throw sp::Error("OrbExtractor::extract: mask must be CV_8UC1 of the image size");
  }
  build_pyramid(gray);
  detect_and_describe(mask, keypoints, descriptors);
}

void OrbExtractor::extract_again(const cv::Mat& mask, std::vector<cv::KeyPoint>& keypoints,
                                 cv::Mat& descriptors, const AgainOptions& options) {
  if (level_size_.empty()) throw sp::Error("OrbExtractor::extract_again: no extract() call before");
  if (mask.empty() || mask.type() != CV_8UC1 || mask.size() != level_size_[0]) {
    throw sp::Error("OrbExtractor::extract_again: mask must be CV_8UC1 of the image size");
  }
  if (options.max_keypoints < 0) throw sp::Error("OrbExtractor::extract_again: max_keypoints must be >= 0");
  // A smaller budget keeps each level's share of it.
  const double share = options.max_keypoints > 0 && options.max_keypoints < config_.n_features
                           ? static_cast<double>(options.max_keypoints) / config_.n_features
                           : 1.0;
  for_each_level([&](int level) {
    const auto l = static_cast<std::size_t>(level);
    const int quota = static_cast<int>(std::lround(per_level_[l] * share));
    if (!options.reuse_detections) {
      process_level(level, mask, quota);
      return;
    }
    if (!level_usable(l, quota)) {
      level_kps_[l].clear();
      level_desc_[l].release();
      return;
    }
    // The corners FAST found on this pyramid and the blurred level are still valid: only the
    // selection among those outside the mask and the descriptors are new.
    LevelScratch& sc = scratch_[l];
    const float scale = static_cast<float>(scale_[l]);
    sc.unmasked.clear();
    for (const cv::KeyPoint& k : sc.found)
      if (!masked_out(mask, k.pt, scale)) sc.unmasked.push_back(k);
    describe_level(level, sc.unmasked, quota, false);
  });
  collect(keypoints, descriptors);
}

template <typename F>
void OrbExtractor::for_each_level(F&& work) {
  if (config_.parallel_levels) {
    // Each level writes only its own buffers, so the result does not depend on scheduling.
    cv::parallel_for_(cv::Range(0, config_.n_levels), [&](const cv::Range& r) {
      for (int l = r.start; l < r.end; ++l) work(l);
    });
  } else {
    for (int l = 0; l < config_.n_levels; ++l) work(l);
  }
}

void OrbExtractor::detect_and_describe(const cv::Mat& mask, std::vector<cv::KeyPoint>& keypoints,
                                       cv::Mat& descriptors) {
  for_each_level([&](int level) { process_level(level, mask, per_level_[static_cast<std::size_t>(level)]); });
  collect(keypoints, descriptors);
}

void OrbExtractor::collect(std::vector<cv::KeyPoint>& keypoints, cv::Mat& descriptors) const {
  std::size_t total = 0;
  for (const auto& v : level_kps_) total += v.size();
  keypoints.clear();
  keypoints.reserve(total);
  descriptors.create(static_cast<int>(total), 32, CV_8UC1);
  int row = 0;
  for (std::size_t l = 0; l < level_kps_.size(); ++l) {
    keypoints.insert(keypoints.end(), level_kps_[l].begin(), level_kps_[l].end());
    if (!level_kps_[l].empty()) {
      level_desc_[l].copyTo(descriptors.rowRange(row, row + static_cast<int>(level_kps_[l].size())));
      row += static_cast<int>(level_kps_[l].size());
    }
  }
}

}  // namespace sp::feat
