#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>

#include "../support/shared_data.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/loop/vocabulary.hpp"

namespace sp::loop {
namespace {

using Desc = std::array<std::uint8_t, kDescriptorBytes>;

Desc flip_bits(Desc d, int n, std::mt19937& rng) {
  std::uniform_int_distribution<int> bit(0, 255);
  for (int i = 0; i < n; ++i) {
    const int b = bit(rng);
    d[b / 8] ^= static_cast<std::uint8_t>(1U << (b % 8));
  }
  return d;
}

Desc random_desc(std::mt19937& rng) {
  Desc d;
  for (auto& b : d) b = static_cast<std::uint8_t>(rng() & 0xFF);
  return d;
}

cv::Mat to_mat(const std::vector<Desc>& ds) {
  cv::Mat m(static_cast<int>(ds.size()), kDescriptorBytes, CV_8U);
  for (std::size_t i = 0; i < ds.size(); ++i)
    std::memcpy(m.ptr(static_cast<int>(i)), ds[i].data(), kDescriptorBytes);
  return m;
}

// Reference greedy descent written independently of Vocabulary's internals.
WordId reference_word(const Vocabulary& v, const std::uint8_t* d) {
  NodeId node = 0;
  for (auto ch = v.children(node); !ch.empty(); ch = v.children(node)) {
    int best = 1 << 30;
    for (NodeId c : ch) {
      const int dist = hamming256(d, v.node_descriptor(c));
      if (dist < best) {
        best = dist;
        node = c;
      }
    }
  }
  for (WordId w = 0; w < v.size(); ++w) {
    if (v.node_of_word(w) == node) return w;
  }
  return ~WordId{0};
}

// Two-level synthetic clusters: 4 random tops, 4 children per top (24 bits from the top), samples
// within 2 bits of a child; 3 "images" per child.
struct Synthetic {
  std::vector<Desc> leaves;
  std::vector<cv::Mat> images;
  std::vector<Desc> samples;
  std::vector<int> sample_leaf;
};

Synthetic make_synthetic(std::uint32_t seed) {
  std::mt19937 rng(seed);
  Synthetic s;
  for (int t = 0; t < 4; ++t) {
    const Desc top = random_desc(rng);
    for (int c = 0; c < 4; ++c) s.leaves.push_back(flip_bits(top, 24, rng));
  }
  for (int img = 0; img < 3; ++img) {
    std::vector<Desc> ds;
    for (std::size_t l = 0; l < s.leaves.size(); ++l) {
      for (int j = 0; j < 10; ++j) {
        ds.push_back(flip_bits(s.leaves[l], 2, rng));
        s.samples.push_back(ds.back());
        s.sample_leaf.push_back(static_cast<int>(l));
      }
    }
    s.images.push_back(to_mat(ds));
  }
  return s;
}

TEST(Vocabulary, GreedyDescentFindsNearestCentreAndLeaf) {
  const Synthetic s = make_synthetic(7);
  VocabularyParams p;
  p.k = 4;
  p.levels = 2;
  const Vocabulary v = Vocabulary::train(s.images, p, 1);
  EXPECT_EQ(v.size(), 16U);
  std::mt19937 rng(3);
  for (int i = 0; i < 300; ++i) {
    const Desc d = i < 200 ? s.samples[static_cast<std::size_t>(i) * 2] : random_desc(rng);
    EXPECT_EQ(v.word_of(d.data()), reference_word(v, d.data()));
  }
  // Well separated clusters: the greedy word is the globally nearest leaf centre, and samples of one
  // synthetic cluster share one word.
  for (std::size_t i = 0; i < s.samples.size(); ++i) {
    const WordId w = v.word_of(s.samples[i].data());
    int best = 1 << 30;
    WordId nearest = 0;
    for (WordId c = 0; c < v.size(); ++c) {
      const int d = hamming256(s.samples[i].data(), v.node_descriptor(v.node_of_word(c)));
      if (d < best) {
        best = d;
        nearest = c;
      }
    }
    ASSERT_EQ(w, nearest) << "sample " << i;
    ASSERT_EQ(w, v.word_of(s.leaves[static_cast<std::size_t>(s.sample_leaf[i])].data()));
  }
}

// Random smooth textures give ORB features; image i+kShift views image i shifted by a few pixels.
std::vector<cv::Mat> textured_images(int n, std::uint32_t seed) {
  cv::RNG rng(seed);
  std::vector<cv::Mat> out;
  for (int i = 0; i < n; ++i) {
    cv::Mat img(240, 320, CV_8U);
    rng.fill(img, cv::RNG::UNIFORM, 0, 255);
    cv::GaussianBlur(img, img, cv::Size(0, 0), 2.0);
    cv::normalize(img, img, 0, 255, cv::NORM_MINMAX);
    out.push_back(img);
  }
  return out;
}

cv::Mat orb(const cv::Mat& img) {
  auto det = cv::ORB::create(300);
  std::vector<cv::KeyPoint> kps;
  cv::Mat d;
  det->detectAndCompute(img, cv::noArray(), kps, d);
  return d;
}

class TrainedVocabulary : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    images_ = textured_images(12, 5);
    for (const auto& img : images_) descriptors_.push_back(orb(img));
    VocabularyParams p;
    p.k = 6;
    p.levels = 3;
    vocab_ = Vocabulary::train(descriptors_, p, 42);
  }
  static std::vector<cv::Mat> images_;
  static std::vector<cv::Mat> descriptors_;
  static Vocabulary vocab_;
};
std::vector<cv::Mat> TrainedVocabulary::images_;
std::vector<cv::Mat> TrainedVocabulary::descriptors_;
Vocabulary TrainedVocabulary::vocab_;

TEST_F(TrainedVocabulary, SelfScoreIsOneOthersLower) {
  ASSERT_GT(vocab_.size(), 50U);
  const BowVector a = vocab_.transform(descriptors_[0]);
  EXPECT_NEAR(l1_score(a, a), 1.0, 1e-9);
  EXPECT_NEAR(a.l1_norm(), 1.0, 1e-9);
  cv::Mat shifted;
  const cv::Mat m = (cv::Mat_<double>(2, 3) << 1, 0, 4, 0, 1, 3);
  cv::warpAffine(images_[0], shifted, m, images_[0].size(), cv::INTER_LINEAR, cv::BORDER_REFLECT);
  const double s_shift = l1_score(a, vocab_.transform(orb(shifted)));
  for (std::size_t i = 1; i < descriptors_.size(); ++i) {
    const double s = l1_score(a, vocab_.transform(descriptors_[i]));
    EXPECT_LT(s, 0.9);
    EXPECT_LT(s, s_shift) << "image " << i;
  }
}

TEST_F(TrainedVocabulary, DirectIndexGroupsFeaturesUnderAncestors) {
  BowVector bow;
  FeatureVector fv;
  vocab_.transform(descriptors_[1], bow, fv, 1);
  std::size_t n = 0;
  for (const auto& [node, idx] : fv) {
    EXPECT_EQ(vocab_.depth(node), vocab_.levels() - 1);
    for (std::uint32_t i : idx) {
      // The feature's word descends from `node`.
      const WordId w = vocab_.word_of(descriptors_[1].ptr<std::uint8_t>(static_cast<int>(i)));
      bool under = false;
      for (NodeId c : vocab_.children(node)) under = under || c == vocab_.node_of_word(w);
      EXPECT_TRUE(under || vocab_.node_of_word(w) == node);
      ++n;
    }
  }
  EXPECT_GT(n, 100U);
}

TEST_F(TrainedVocabulary, SaveLoadRoundTrip) {
  const std::filesystem::path dir = SP_TEST_TMP_DIR;
  std::filesystem::create_directories(dir);
  const auto file = dir / "vocab_roundtrip.spv";
  vocab_.save(file);
  const Vocabulary loaded = Vocabulary::load(file);
  EXPECT_TRUE(loaded == vocab_);
  EXPECT_EQ(loaded.transform(descriptors_[3]), vocab_.transform(descriptors_[3]));
}

std::string read_all(const std::filesystem::path& f) {
  std::ifstream in(f, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}
void write_all(const std::filesystem::path& f, const std::string& s) {
  std::ofstream out(f, std::ios::binary | std::ios::trunc);
  out << s;
}

void expect_rejected(const std::filesystem::path& f, const std::string& fragment) {
  try {
    (void)Vocabulary::load(f);
    FAIL() << "accepted " << f;
  } catch (const sp::InputError& e) {
    EXPECT_EQ(e.file(), f.string());
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
  }
}

TEST_F(TrainedVocabulary, BadFilesAreRejected) {
  const std::filesystem::path dir = SP_TEST_TMP_DIR;
  std::filesystem::create_directories(dir);
  const auto good = dir / "vocab_good.spv";
  vocab_.save(good);
  const std::string bytes = read_all(good);

  const auto truncated = dir / "vocab_truncated.spv";
  write_all(truncated, bytes.substr(0, bytes.size() / 2));
  expect_rejected(truncated, "truncated");

  std::string corrupt = bytes;
  corrupt[corrupt.size() / 2] = static_cast<char>(corrupt[corrupt.size() / 2] ^ 0x10);
  const auto corrupt_file = dir / "vocab_corrupt.spv";
  write_all(corrupt_file, corrupt);
  expect_rejected(corrupt_file, "checksum");

  std::string wrong_version = bytes;
  wrong_version[8] = 9;
  const auto version_file = dir / "vocab_version.spv";
  write_all(version_file, wrong_version);
  expect_rejected(version_file, "version 9");

  const auto text = dir / "vocab_text.spv";
  write_all(text, "hello, this is not a vocabulary at all");
  expect_rejected(text, "magic");
  expect_rejected(dir / "does_not_exist.spv", "cannot read");
}

TEST_F(TrainedVocabulary, TrainingIsDeterministicForASeed) {
  VocabularyParams p;
  p.k = 6;
  p.levels = 3;
  EXPECT_TRUE(Vocabulary::train(descriptors_, p, 42) == vocab_);
}

}  // namespace
}  // namespace sp::loop

namespace sp::loop {
namespace {

TEST(ShippedVocabulary, LoadsAndDescribesRealFrames) {
  const std::filesystem::path file = std::filesystem::path(SP_SOURCE_DIR) / "data/vocab/stillpoint_orb.spv";
  const Vocabulary v = Vocabulary::load(file);
  EXPECT_EQ(v.branching(), 10);
  EXPECT_EQ(v.levels(), 5);
  EXPECT_GT(v.size(), 50000U);
  EXPECT_LE(v.size(), 100000U);
  const auto dir = std::filesystem::path(SP_SHARED_DIR) / "data/dynsynth/office_a_static_xyz_150/rgb";
  SP_REQUIRE_SHARED(dir);
  std::vector<std::filesystem::path> frames;
  for (const auto& e : std::filesystem::directory_iterator(dir)) frames.push_back(e.path());
  std::sort(frames.begin(), frames.end());
  ASSERT_GE(frames.size(), 100U);
  const auto bow_of = [&](const std::filesystem::path& f) {
    return v.transform(orb(cv::imread(f.string(), cv::IMREAD_GRAYSCALE)));
  };
  const BowVector a = bow_of(frames[0]);
  EXPECT_GT(a.size(), 100U);
  EXPECT_NEAR(l1_score(a, a), 1.0, 1e-9);
  // The next frame (33 ms later) looks more alike than a frame of the same desk seconds later.
  EXPECT_GT(l1_score(a, bow_of(frames[1])), l1_score(a, bow_of(frames[99])));
}

}  // namespace
}  // namespace sp::loop

namespace sp::loop {
namespace {

TEST(VocabularyParams, ReadsAndChecksYaml) {
  const auto r = sp::ConfigReader::from_string("k: 8\nlevels: 6\n", "vocab.yaml");
  const VocabularyParams p = VocabularyParams::from_yaml(r);
  r.finish();
  EXPECT_EQ(p.k, 8);
  EXPECT_EQ(p.levels, 6);
  EXPECT_THROW(VocabularyParams::from_yaml(sp::ConfigReader::from_string("k: 1\n", "bad.yaml")),
               sp::ConfigError);
  VocabularyParams bad;
  bad.levels = 0;
  EXPECT_THROW(Vocabulary::train({cv::Mat(4, 32, CV_8U, cv::Scalar(1))}, bad, 1), sp::Error);
  EXPECT_THROW(Vocabulary::train({}, VocabularyParams{}, 1), sp::Error);
}

}  // namespace
}  // namespace sp::loop
