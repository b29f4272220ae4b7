// Colour JPEGs decoded straight to BGR against cv::imread, and the files left to cv::imread.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "stillpoint/io/jpeg_reader.hpp"

namespace sp::io {
namespace {

namespace fs = std::filesystem;

fs::path scratch_dir() {
  const fs::path d =
      fs::temp_directory_path() / fs::path("sp_jpeg_reader").concat(std::to_string(::getpid()));
  fs::create_directories(d);
  return d;
}

cv::Mat textured(int rows, int cols) {
  cv::Mat img(rows, cols, CV_8UC3);
  cv::RNG rng(7);
  rng.fill(img, cv::RNG::UNIFORM, 0, 255);
  cv::GaussianBlur(img, img, cv::Size(5, 5), 1.5);
  cv::rectangle(img, cv::Rect(10, 10, 40, 20), cv::Scalar(0, 0, 255), cv::FILLED);  // a pure red patch
  return img;
}

bool same(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0.0;
}

std::vector<unsigned char> read_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

TEST(JpegReader, ColourJpegsGiveCvImreadsPixels) {
  const fs::path dir = scratch_dir();
  for (const int quality : {60, 95}) {
    for (const bool progressive : {false, true}) {
      std::string name = "c";
      name += std::to_string(quality);
      name += progressive ? "p.jpg" : "b.jpg";
      const fs::path file = dir / name;
      ASSERT_TRUE(cv::imwrite(
          file.string(), textured(97, 131),
          {cv::IMWRITE_JPEG_QUALITY, quality, cv::IMWRITE_JPEG_PROGRESSIVE, progressive ? 1 : 0}));
      const cv::Mat ref = cv::imread(file.string(), cv::IMREAD_COLOR);
      ASSERT_FALSE(ref.empty());
      EXPECT_TRUE(same(read_color_image(file.string()), ref)) << file;
      const cv::Mat direct = decode_jpeg_bgr(file.string());
      if (direct_jpeg_decoding()) {
        ASSERT_FALSE(direct.empty()) << file;
        EXPECT_TRUE(same(direct, ref)) << file;
        // BGR order: the red patch is red.
        EXPECT_GT(direct.at<cv::Vec3b>(20, 30)[2], 200);
        EXPECT_LT(direct.at<cv::Vec3b>(20, 30)[0], 60);
      } else {
        EXPECT_TRUE(direct.empty());
      }
    }
  }
  fs::remove_all(dir);
}

TEST(JpegReader, GreyExifRotatedAndOtherFilesAreLeftToCvImread) {
  const fs::path dir = scratch_dir();
  // A grey JPEG: cv::imread makes three channels of it.
  cv::Mat grey;
  cv::cvtColor(textured(40, 60), grey, cv::COLOR_BGR2GRAY);
  const fs::path grey_file = dir / "grey.jpg";
  ASSERT_TRUE(cv::imwrite(grey_file.string(), grey));
  EXPECT_TRUE(decode_jpeg_bgr(grey_file.string()).empty());
  EXPECT_TRUE(same(read_color_image(grey_file.string()), cv::imread(grey_file.string(), cv::IMREAD_COLOR)));

  // A colour JPEG with an EXIF orientation of 6 (rotate 90°): cv::imread turns it upright.
  const fs::path plain = dir / "plain.jpg";
  ASSERT_TRUE(cv::imwrite(plain.string(), textured(40, 60)));
  std::vector<unsigned char> bytes = read_bytes(plain);
  const std::vector<unsigned char> exif = {
      0xFF, 0xE1, 0x00, 0x22, 'E',  'x',  'i',  'f',  0,    0,                 // APP1, length 34, "Exif\0\0"
      'I',  'I',  0x2A, 0x00, 0x08, 0x00, 0x00, 0x00,                          // TIFF header, IFD at 8
      0x01, 0x00,                                                              // one entry
      0x12, 0x01, 0x03, 0x00, 0x01, 0x00, 0x00, 0x00, 0x06, 0x00, 0x00, 0x00,  // Orientation = 6
      0x00, 0x00, 0x00, 0x00};                                                 // no next IFD
  bytes.insert(bytes.begin() + 2, exif.begin(), exif.end());
  const fs::path rotated = dir / "rotated.jpg";
  {
    std::ofstream out(rotated, std::ios::binary);
    out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  }
  const cv::Mat ref = cv::imread(rotated.string(), cv::IMREAD_COLOR);
  ASSERT_EQ(ref.rows, 60);  // the test file really is rotated by cv::imread
  EXPECT_TRUE(decode_jpeg_bgr(rotated.string()).empty());
  EXPECT_TRUE(same(read_color_image(rotated.string()), ref));

  // Not a JPEG, and no file at all.
  const fs::path png = dir / "c.png";
  ASSERT_TRUE(cv::imwrite(png.string(), textured(20, 30)));
  EXPECT_TRUE(decode_jpeg_bgr(png.string()).empty());
  EXPECT_TRUE(same(read_color_image(png.string()), cv::imread(png.string(), cv::IMREAD_COLOR)));
  EXPECT_TRUE(read_color_image((dir / "missing.jpg").string()).empty());

  // A JPEG cut short after its header: whatever cv::imread makes of it, the same.
  std::vector<unsigned char> cut = read_bytes(plain);
  cut.resize(cut.size() / 3);
  const fs::path cut_file = dir / "cut.jpg";
  {
    std::ofstream out(cut_file, std::ios::binary);
    out.write(reinterpret_cast<const char*>(cut.data()), static_cast<std::streamsize>(cut.size()));
  }
  const cv::Mat cut_ref = cv::imread(cut_file.string(), cv::IMREAD_COLOR);
  const cv::Mat cut_ours = read_color_image(cut_file.string());
  EXPECT_EQ(cut_ours.empty(), cut_ref.empty());
  if (!cut_ref.empty()) {
    EXPECT_TRUE(same(cut_ours, cut_ref));
  }
  fs::remove_all(dir);
}

}  // namespace
}  // namespace sp::io
