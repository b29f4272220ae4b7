#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "../support/shared_data.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/features/matching.hpp"
#include "stillpoint/features/orb_extractor.hpp"

namespace sp::feat {
namespace {

const std::filesystem::path kFrames =
    std::filesystem::path(SP_SHARED_DIR) / "data/dynsynth/office_a_static_xyz_150/rgb";

cv::Mat load_frame(int index = 0) {
  std::vector<std::filesystem::path> files;
  for (const auto& e : std::filesystem::directory_iterator(kFrames)) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  if (files.size() <= static_cast<std::size_t>(index)) return {};
  return cv::imread(files[static_cast<std::size_t>(index)].string(), cv::IMREAD_GRAYSCALE);
}

struct Extracted {
  std::vector<cv::KeyPoint> kps;
  cv::Mat desc;
};

Extracted run(OrbExtractor& orb, const cv::Mat& img, const cv::Mat& mask = cv::Mat()) {
  Extracted e;
  orb.extract(img, e.kps, e.desc, mask);
  return e;
}

// Share of matches whose keypoints agree with the known point mapping `map` (within a tolerance
// that grows with the pyramid level, since coarse levels localise less precisely).
template <typename Map>
double consistent_share(const Extracted& a, const Extracted& b, Map map, std::size_t* n_matches) {
  const auto matches = match_ratio(a.desc, b.desc, 0.8f, 64, true);
  *n_matches = matches.size();
  ::testing::Test::RecordProperty("matches", static_cast<int>(matches.size()));
  if (matches.empty()) return 0.0;
  int good = 0;
  for (const auto& m : matches) {
    const cv::KeyPoint& ka = a.kps[static_cast<std::size_t>(m.query)];
    const cv::KeyPoint& kb = b.kps[static_cast<std::size_t>(m.train)];
    const cv::Point2f p = map(ka.pt);
    const double tol = 3.0 * std::pow(1.2, std::max(ka.octave, kb.octave));
    if (cv::norm(p - kb.pt) < tol) ++good;
  }
  const double share = static_cast<double>(good) / static_cast<double>(matches.size());
  ::testing::Test::RecordProperty("consistent_share", std::to_string(share));
  return share;
}

TEST(OrbExtractor, LevelScalesAndBudget) {
  OrbExtractor orb(OrbConfig{});
  ASSERT_EQ(orb.levels(), 8);
  EXPECT_DOUBLE_EQ(orb.scale_factor(), 1.2);
  EXPECT_NEAR(orb.scale_factors()[3], 1.728, 1e-12);
  EXPECT_NEAR(orb.inv_scale_factors()[3], 1.0 / 1.728, 1e-12);
  EXPECT_NEAR(orb.level_sigma2()[2], 1.44 * 1.44, 1e-12);
  EXPECT_NEAR(orb.inv_level_sigma2()[2], 1.0 / (1.44 * 1.44), 1e-12);
  int sum = 0;
  for (int n : orb.features_per_level()) sum += n;
  EXPECT_EQ(sum, 1000);
  // Geometric split: level 0 holds 1000 * (1 - 1/1.2) / (1 - 1.2^-8) = 217.2 features.
  EXPECT_EQ(orb.features_per_level()[0], 217);
  EXPECT_EQ(orb.features_per_level()[1], 181);
}

TEST(OrbExtractor, ConfigFromYamlChecksRanges) {
  const auto ok = OrbConfig::from_yaml(ConfigReader::from_string("n_features: 1500\nn_levels: 4\n", "t"));
  EXPECT_EQ(ok.n_features, 1500);
  EXPECT_EQ(ok.n_levels, 4);
  EXPECT_EQ(ok.fast_threshold, 20);
  EXPECT_THROW(OrbConfig::from_yaml(ConfigReader::from_string("scale_factor: 0.9\n", "t")), ConfigError);
  EXPECT_THROW(OrbConfig::from_yaml(ConfigReader::from_string("fast_threshold: 5\n", "t")), ConfigError);
  EXPECT_THROW(OrbConfig::from_yaml(ConfigReader::from_string("pattern: learned\n", "t")), ConfigError);
  EXPECT_EQ(OrbConfig::from_yaml(ConfigReader::from_string("pattern: decorrelated\n", "t")).pattern,
            "decorrelated");
  OrbConfig bad;
  bad.n_levels = 0;
  EXPECT_THROW(OrbExtractor{bad}, sp::Error);
}

TEST(OrbExtractor, CountNearTargetAndOutputLayout) {
  SP_REQUIRE_SHARED(kFrames);
  const cv::Mat img = load_frame();
  ASSERT_FALSE(img.empty());
  OrbExtractor orb(OrbConfig{});
  const Extracted e = run(orb, img);
  EXPECT_GE(e.kps.size(), 900u);
  EXPECT_LE(e.kps.size(), 1100u);
  ASSERT_EQ(e.desc.rows, static_cast<int>(e.kps.size()));
  EXPECT_EQ(e.desc.cols, 32);
  EXPECT_EQ(e.desc.type(), CV_8UC1);
  for (const auto& k : e.kps) {
    ASSERT_GE(k.octave, 0);
    ASSERT_LT(k.octave, 8);
    EXPECT_FLOAT_EQ(k.size,
                    static_cast<float>(31.0 * orb.scale_factors()[static_cast<std::size_t>(k.octave)]));
    EXPECT_GE(k.angle, 0.f);
    EXPECT_LT(k.angle, 360.f);
    EXPECT_GT(k.response, 0.f);
    EXPECT_GE(k.pt.x, 0.f);
    EXPECT_GE(k.pt.y, 0.f);
    EXPECT_LT(k.pt.x, static_cast<float>(img.cols));
    EXPECT_LT(k.pt.y, static_cast<float>(img.rows));
  }
  // A blank image gives nothing, without failing.
  const Extracted blank = run(orb, cv::Mat(480, 640, CV_8UC1, cv::Scalar(128)));
  EXPECT_TRUE(blank.kps.empty());
  EXPECT_EQ(blank.desc.rows, 0);
  EXPECT_THROW(run(orb, cv::Mat(480, 640, CV_8UC3)), sp::Error);
}

TEST(OrbExtractor, SpatiallyUniformerThanFastTopN) {
  SP_REQUIRE_SHARED(kFrames);
  const cv::Mat img = load_frame();
  ASSERT_FALSE(img.empty());
  OrbExtractor orb(OrbConfig{});
  const Extracted e = run(orb, img);

  std::vector<cv::KeyPoint> fast;
  cv::FAST(img, fast, 7, true);
  std::sort(fast.begin(), fast.end(), [](const auto& a, const auto& b) { return a.response > b.response; });
  fast.resize(std::min(fast.size(), e.kps.size()));

  const auto cell_counts = [&](const std::vector<cv::KeyPoint>& kps, int g = 4) {
    std::vector<int> c(static_cast<std::size_t>(g * g), 0);
    for (const auto& k : kps) {
      const int cx =
          std::min(g - 1, static_cast<int>(k.pt.x * static_cast<float>(g) / static_cast<float>(img.cols)));
      const int cy =
          std::min(g - 1, static_cast<int>(k.pt.y * static_cast<float>(g) / static_cast<float>(img.rows)));
      ++c[static_cast<std::size_t>(cy * g + cx)];
    }
    return c;
  };
  const auto max_over_mean = [](const std::vector<int>& c) {
    double sum = 0;
    for (int v : c) sum += v;
    return *std::max_element(c.begin(), c.end()) / (sum / static_cast<double>(c.size()));
  };
  const std::vector<int> ours = cell_counts(e.kps);
  for (int i = 0; i < 16; ++i) {
    const cv::Rect r((i % 4) * img.cols / 4, (i / 4) * img.rows / 4, img.cols / 4, img.rows / 4);
    cv::Scalar mean, stddev;
    cv::meanStdDev(img(r), mean, stddev);
    if (stddev[0] > 8.0) {
      EXPECT_GT(ours[static_cast<std::size_t>(i)], 0) << "textured cell " << i;
    }
  }
  const double ours_ratio = max_over_mean(ours);
  const double fast_ratio = max_over_mean(cell_counts(fast));
  RecordProperty("max_over_mean_orb", std::to_string(ours_ratio));
  RecordProperty("max_over_mean_fast", std::to_string(fast_ratio));
  EXPECT_LT(ours_ratio, 0.85 * fast_ratio) << "orb " << ours_ratio << " fast " << fast_ratio;
  // On a finer 8x8 grid the distributed keypoints also reach more cells.
  const auto occupied = [](const std::vector<int>& c) {
    return std::count_if(c.begin(), c.end(), [](int v) { return v > 0; });
  };
  EXPECT_GT(occupied(cell_counts(e.kps, 8)), occupied(cell_counts(fast, 8)));
}

TEST(OrbExtractor, MaskIsRespected) {
  SP_REQUIRE_SHARED(kFrames);
  const cv::Mat img = load_frame();
  ASSERT_FALSE(img.empty());
  cv::Mat mask(img.size(), CV_8UC1, cv::Scalar(255));
  const cv::Rect blocked(200, 100, 240, 260);
  mask(blocked).setTo(0);
  OrbExtractor orb(OrbConfig{});
  const Extracted e = run(orb, img, mask);
  ASSERT_GT(e.kps.size(), 500u);
  for (const auto& k : e.kps) {
    const int x = static_cast<int>(std::lround(k.pt.x)), y = static_cast<int>(std::lround(k.pt.y));
    ASSERT_FALSE(blocked.contains({x, y})) << k.pt << " octave " << k.octave;
  }
  EXPECT_THROW(run(orb, img, cv::Mat(10, 10, CV_8UC1)), sp::Error);
}

// Re-selection among the first pass's corners: with nothing masked and the whole budget it must
// reproduce the first pass exactly (same candidates, same blurred level, same descriptors); with a
// mask and a smaller budget it stays out of the mask and within the budget, and its descriptors are
// those a fresh extraction computes at the same keypoints.
TEST(OrbExtractor, ExtractAgainReusingCorners) {
  SP_REQUIRE_SHARED(kFrames);
  const cv::Mat img = load_frame(3);
  ASSERT_FALSE(img.empty());
  OrbExtractor orb(OrbConfig{});
  const Extracted first = run(orb, img);
  Extracted again;
  const cv::Mat open(img.size(), CV_8UC1, cv::Scalar(255));
  orb.extract_again(open, again.kps, again.desc, {});
  ASSERT_EQ(first.kps.size(), again.kps.size());
  for (std::size_t i = 0; i < first.kps.size(); ++i) {
    EXPECT_EQ(first.kps[i].pt, again.kps[i].pt);
    EXPECT_EQ(first.kps[i].angle, again.kps[i].angle);
  }
  EXPECT_EQ(cv::norm(first.desc, again.desc, cv::NORM_L1), 0.0);

  cv::Mat mask = open.clone();
  const cv::Rect blocked(100, 80, 300, 250);
  mask(blocked).setTo(0);
  OrbExtractor::AgainOptions options;
  options.max_keypoints = 300;
  orb.extract_again(mask, again.kps, again.desc, options);
  EXPECT_LE(again.kps.size(), 305u);  // per-level rounding
  EXPECT_GT(again.kps.size(), 200u) << "the unmasked part of the frame has corners to spare";
  ASSERT_EQ(again.desc.rows, static_cast<int>(again.kps.size()));
  // Every re-selected keypoint is one of the first pass's candidates: a fresh extraction outside the
  // same mask with a whole budget finds it with the same descriptor.
  OrbExtractor fresh(OrbConfig{});
  Extracted all;
  fresh.extract(img, all.kps, all.desc, mask);
  std::size_t found = 0;
  for (std::size_t i = 0; i < again.kps.size(); ++i) {
    const cv::KeyPoint& k = again.kps[i];
    ASSERT_FALSE(
        blocked.contains({static_cast<int>(std::lround(k.pt.x)), static_cast<int>(std::lround(k.pt.y))}))
        << k.pt;
    for (std::size_t j = 0; j < all.kps.size(); ++j) {
      if (all.kps[j].octave == k.octave && cv::norm(all.kps[j].pt - k.pt) < 1e-3) {
        EXPECT_EQ(cv::norm(again.desc.row(static_cast<int>(i)), all.desc.row(static_cast<int>(j)),
                           cv::NORM_HAMMING),
                  0.0);
        ++found;
        break;
      }
    }
  }
  // The fresh pass may retry emptied cells with the low FAST threshold and select differently, so
  // most, not all, re-selected keypoints appear in it.
  EXPECT_GT(found, again.kps.size() / 2);
  EXPECT_THROW(orb.extract_again(mask, again.kps, again.desc, {.max_keypoints = -1}), sp::Error);
}

TEST(OrbExtractor, DeterministicAndParallelIdentical) {
  SP_REQUIRE_SHARED(kFrames);
  const cv::Mat img = load_frame(5);
  ASSERT_FALSE(img.empty());
  OrbExtractor a(OrbConfig{});
  OrbConfig pc;
  pc.parallel_levels = true;
  OrbExtractor b(pc);
  const Extracted e1 = run(a, img), e2 = run(a, img), e3 = run(b, img);
  for (const Extracted* other : {&e2, &e3}) {
    ASSERT_EQ(e1.kps.size(), other->kps.size());
    for (std::size_t i = 0; i < e1.kps.size(); ++i) {
      EXPECT_EQ(e1.kps[i].pt, other->kps[i].pt);
      EXPECT_EQ(e1.kps[i].angle, other->kps[i].angle);
      EXPECT_EQ(e1.kps[i].octave, other->kps[i].octave);
      EXPECT_EQ(e1.kps[i].response, other->kps[i].response);
    }
    EXPECT_EQ(cv::norm(e1.desc, other->desc, cv::NORM_L1), 0.0);
  }
}

TEST(OrbExtractor, InvariantToRotation30) {
  SP_REQUIRE_SHARED(kFrames);
  const cv::Mat img = load_frame();
  ASSERT_FALSE(img.empty());
  const cv::Point2f centre(0.5f * (img.cols - 1), 0.5f * (img.rows - 1));
  const cv::Mat rot = cv::getRotationMatrix2D(centre, 30.0, 1.0);
  cv::Mat turned;
  cv::warpAffine(img, turned, rot, img.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  OrbExtractor orb(OrbConfig{});
  const Extracted a = run(orb, img), b = run(orb, turned);
  std::size_t n = 0;
  const double share = consistent_share(
      a, b,
      [&](const cv::Point2f& p) {
        return cv::Point2f(static_cast<float>(rot.at<double>(0, 0) * p.x + rot.at<double>(0, 1) * p.y +
                                              rot.at<double>(0, 2)),
                           static_cast<float>(rot.at<double>(1, 0) * p.x + rot.at<double>(1, 1) * p.y +
                                              rot.at<double>(1, 2)));
      },
      &n);
  EXPECT_GT(n, 150u);
  EXPECT_GT(share, 0.6) << n << " matches";
}

TEST(OrbExtractor, InvariantToRotation90WithConsistentAngles) {
  SP_REQUIRE_SHARED(kFrames);
  const cv::Mat img = load_frame();
  ASSERT_FALSE(img.empty());
  cv::Mat turned;
  cv::rotate(img, turned, cv::ROTATE_90_CLOCKWISE);  // (x, y) -> (rows - 1 - y, x)
  OrbExtractor orb(OrbConfig{});
  const Extracted a = run(orb, img), b = run(orb, turned);
  std::size_t n = 0;
  const auto map = [&](const cv::Point2f& p) {
    return cv::Point2f(static_cast<float>(img.rows - 1) - p.y, p.x);
  };
  const double share = consistent_share(a, b, map, &n);
  EXPECT_GT(n, 200u);
  EXPECT_GT(share, 0.6) << n << " matches";
  // In image coordinates that rotation adds +90 degrees to every keypoint angle.
  RotationHistogram hist(30);
  const auto matches = match_ratio(a.desc, b.desc, 0.8f, 64, true);
  for (std::size_t i = 0; i < matches.size(); ++i) {
    hist.add(b.kps[static_cast<std::size_t>(matches[i].train)].angle -
                 a.kps[static_cast<std::size_t>(matches[i].query)].angle,
             i);
  }
  int near90 = 0;
  for (std::size_t i : hist.inliers()) {
    const float d = std::fmod(b.kps[static_cast<std::size_t>(matches[i].train)].angle -
                                  a.kps[static_cast<std::size_t>(matches[i].query)].angle + 720.f,
                              360.f);
    near90 += std::abs(d - 90.f) < 20.f ? 1 : 0;
  }
  EXPECT_GT(near90, static_cast<int>(0.6 * static_cast<double>(matches.size())));
}

TEST(OrbExtractor, InvariantToScale144) {
  SP_REQUIRE_SHARED(kFrames);
  const cv::Mat img = load_frame();
  ASSERT_FALSE(img.empty());
  const double s = 1.44;
  cv::Mat small;
  cv::resize(
      img, small,
      cv::Size(static_cast<int>(std::lround(img.cols / s)), static_cast<int>(std::lround(img.rows / s))), 0,
      0, cv::INTER_AREA);
  OrbExtractor orb(OrbConfig{});
  const Extracted a = run(orb, img), b = run(orb, small);
  std::size_t n = 0;
  const double share = consistent_share(
      a, b, [&](const cv::Point2f& p) { return p * static_cast<float>(1.0 / s); }, &n);
  EXPECT_GT(n, 100u);
  EXPECT_GT(share, 0.6) << n << " matches";
}

}  // namespace
}  // namespace sp::feat
