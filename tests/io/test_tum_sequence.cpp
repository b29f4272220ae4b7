#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <fstream>
#include <future>
#include <memory>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <string>
#include <thread>

#include "../support/shared_data.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/io/tum_sequence.hpp"
#include "stillpoint/io/tum_text.hpp"
#include "test_util.hpp"

namespace sp::io {
namespace {

namespace fs = std::filesystem;
const fs::path kSeq = SP_SHARED_DIR "/data/dynsynth/office_a_static_xyz_150";

TEST(TumSequence, ReadsTheWholeSharedSequence) {
  SP_REQUIRE_SHARED(kSeq / "associations.txt");
  TumSequence seq(kSeq);
  const auto assoc = read_tum_text(kSeq / "associations.txt", 4);
  ASSERT_EQ(seq.size_hint(), 150u);
  ASSERT_EQ(assoc.size(), 150u);
  EXPECT_DOUBLE_EQ(seq.camera().intrinsics.fx, 535.4);
  ASSERT_TRUE(seq.groundtruth_path().has_value());
  EXPECT_EQ(*seq.groundtruth_path(), kSeq / "groundtruth.txt");

  std::size_t n = 0;
  double last = -1;
  while (auto f = seq.next()) {
    EXPECT_EQ(f->index, n);
    EXPECT_DOUBLE_EQ(f->stamp, assoc[n].stamp);
    EXPECT_NEAR(f->depth_stamp, f->stamp, 0.02);
    EXPECT_GT(f->stamp, last);
    last = f->stamp;
    ASSERT_EQ(f->bgr.type(), CV_8UC3);
    ASSERT_EQ(f->depth.type(), CV_32FC1);
    EXPECT_EQ(f->bgr.size(), cv::Size(640, 480));
    EXPECT_EQ(f->depth.size(), cv::Size(640, 480));
    if (n % 50 == 0) {
      // Metres: an office seen from a desk is 0.3–8 m away; most pixels have a reading.
      const cv::Mat valid = f->depth > 0;
      EXPECT_GT(cv::countNonZero(valid), 640 * 480 / 2);
      double lo = 0, hi = 0;
      cv::minMaxLoc(f->depth, &lo, &hi, nullptr, nullptr, valid);
      EXPECT_GE(lo, 0.1);
      EXPECT_LE(hi, 8.0);
      EXPECT_GT(cv::mean(f->depth, valid)[0], 0.5);
      // Exactly raw / 5000.
      const cv::Mat raw = cv::imread((kSeq / assoc[n].columns[3]).string(), cv::IMREAD_UNCHANGED);
      EXPECT_FLOAT_EQ(f->depth.at<float>(240, 320), raw.at<std::uint16_t>(240, 320) / 5000.0f);
    }
    ++n;
  }
  EXPECT_EQ(n, 150u);
  EXPECT_EQ(seq.skipped_frames(), 0u);
  EXPECT_FALSE(seq.next().has_value());  // stays at the end
}

TEST(TumSequence, StartAndMaxFramesSelectAWindow) {
  SP_REQUIRE_SHARED(kSeq / "associations.txt");
  TumSequenceOptions o;
  o.start_frame = 5;
  o.max_frames = 4;
  o.prefetch = 1;
  TumSequence seq(kSeq, o);
  EXPECT_EQ(seq.size_hint(), 4u);
  std::vector<std::size_t> idx;
  while (auto f = seq.next()) idx.push_back(f->index);
  EXPECT_EQ(idx, (std::vector<std::size_t>{5, 6, 7, 8}));
}

// The niceness of each of this process's threads, from /proc/self/task/TID/stat (field 19; the
// command name in field 2 is parenthesised and may hold spaces, so fields are counted after its ')').
std::vector<int> thread_nice_values() {
  std::vector<int> out;
  for (const auto& task : fs::directory_iterator("/proc/self/task")) {
    std::ifstream in(task.path() / "stat");
    std::string stat((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const auto close = stat.rfind(')');
    if (close == std::string::npos) continue;
    std::istringstream rest(stat.substr(close + 1));
    std::string field;
    for (int k = 3; k <= 19 && rest >> field; ++k)
      if (k == 19) out.push_back(std::stoi(field));
  }
  return out;
}

// The reader decodes ahead at lower priority, so tracking and the detector win the shared cores.
TEST(TumSequence, ReaderThreadRunsAtTheAskedNiceness) {
  SP_REQUIRE_SHARED(kSeq / "associations.txt");
  const std::vector<int> before = thread_nice_values();
  ASSERT_FALSE(before.empty());
  const int base = before.front();                        // this (main) thread
  const int asked = std::min(std::max(base + 1, 7), 19);  // niceness is absolute (setpriority)
  if (asked <= base) GTEST_SKIP() << "the test process already runs at niceness " << base;
  TumSequenceOptions o;
  o.prefetch = 1;  // the reader stays alive, blocked on the full queue
  o.reader_nice = asked;
  TumSequence seq(kSeq, o);
  ASSERT_TRUE(seq.next().has_value());  // the reader has started and lowered itself
  const std::vector<int> during = thread_nice_values();
  EXPECT_EQ(std::count(during.begin(), during.end(), asked),
            std::count(before.begin(), before.end(), asked) + 1);
  EXPECT_EQ(during.front(), base);  // the caller keeps its priority
}

// The reader thread blocks on the full prefetch queue; the destructor must wake and join it. The
// destruction runs on a detached thread so that a hang is reported as a failure after a bounded wait
// (generous: the whole body reads 3 frames; this is a hang detector, not a timing check) instead of
// blocking the test binary until CTest's timeout.
TEST(TumSequence, DestructorStopsTheReaderMidSequence) {
  SP_REQUIRE_SHARED(kSeq / "associations.txt");
  TumSequenceOptions o;
  o.prefetch = 2;
  auto first_frames = std::make_shared<std::promise<int>>();
  std::future<int> done = first_frames->get_future();
  std::thread([first_frames, o, dir = kSeq] {
    int got = 0;
    try {
      for (int k = 0; k < 3; ++k) {
        TumSequence seq(dir, o);
        got += seq.next().has_value() ? 1 : 0;
        std::this_thread::sleep_for(std::chrono::milliseconds(100));  // the reader fills the queue
      }  // the destructor stops the reader blocked on the full queue
      first_frames->set_value(got);
    } catch (...) {
      first_frames->set_exception(std::current_exception());
    }
  }).detach();
  ASSERT_EQ(done.wait_for(std::chrono::seconds(30)), std::future_status::ready)
      << "TumSequence's destructor did not return within 30 s: the reader thread stayed blocked";
  EXPECT_EQ(done.get(), 3);  // each of the three sequences gave its first frame before being destroyed
}

// A 10-frame copy without associations.txt (so rgb.txt/depth.txt are associated), with frame 3's colour
// image corrupt, frame 6's depth missing and frame 8's depth of the wrong size.
fs::path damaged_copy() {
  const fs::path dir = test::scratch_dir();
  fs::create_directories(dir / "rgb");
  fs::create_directories(dir / "depth");
  fs::copy_file(kSeq / "camera.yaml", dir / "camera.yaml");
  const auto assoc = read_tum_text(kSeq / "associations.txt", 4);
  std::string rgb = "# color images\n", depth = "# depth maps\n";
  for (std::size_t k = 0; k < 10; ++k) {
    rgb += assoc[k].columns[0] + " " + assoc[k].columns[1] + "\n";
    depth += assoc[k].columns[2] + " " + assoc[k].columns[3] + "\n";
    fs::copy_file(kSeq / assoc[k].columns[1], dir / assoc[k].columns[1]);
    if (k != 6) fs::copy_file(kSeq / assoc[k].columns[3], dir / assoc[k].columns[3]);
  }
  test::write_text(dir / "rgb.txt", rgb);
  test::write_text(dir / "depth.txt", depth);
  test::write_text(dir / assoc[3].columns[1], "this is not a jpeg");
  const cv::Mat d = cv::imread((kSeq / assoc[8].columns[3]).string(), cv::IMREAD_UNCHANGED);
  cv::Mat small;
  cv::resize(d, small, cv::Size(320, 240), 0, 0, cv::INTER_NEAREST);
  cv::imwrite((dir / assoc[8].columns[3]).string(), small);
  return dir;
}

TEST(TumSequence, BadFramesAreSkippedCountedAndTheRunGoesOn) {
  SP_REQUIRE_SHARED(kSeq / "associations.txt");
  const fs::path dir = damaged_copy();
  TumSequence seq(dir);
  EXPECT_EQ(seq.size_hint(), 10u);
  EXPECT_FALSE(seq.groundtruth_path().has_value());
  std::vector<std::size_t> idx;
  while (auto f = seq.next()) {
    idx.push_back(f->index);
    EXPECT_FALSE(f->depth.empty());
  }
  EXPECT_EQ(idx, (std::vector<std::size_t>{0, 1, 2, 4, 5, 7, 9}));
  EXPECT_EQ(seq.skipped_frames(), 3u);
}

TEST(TumSequence, CameraFileOptionAndMissingCamera) {
  SP_REQUIRE_SHARED(kSeq / "associations.txt");
  const fs::path dir = damaged_copy();
  fs::remove(dir / "camera.yaml");
  EXPECT_THROW(TumSequence seq(dir), InputError);
  TumSequenceOptions o;
  o.camera_file = fs::path(SP_SOURCE_DIR "/config/camera/dynsynth.yaml");
  TumSequence seq(dir, o);
  EXPECT_DOUBLE_EQ(seq.camera().intrinsics.cx, 320.1);
  EXPECT_THROW(TumSequence bad(dir / "nope"), InputError);
}

TEST(TumSequence, MalformedListIsAnErrorAtConstruction) {
  SP_REQUIRE_SHARED(kSeq / "associations.txt");
  const fs::path dir = damaged_copy();
  test::write_text(dir / "rgb.txt", "1.0 rgb/a.jpg\n0.5 rgb/b.jpg\n");
  try {
    TumSequence seq(dir);
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(e.line(), 2);
    EXPECT_EQ(e.file(), (dir / "rgb.txt").string());
  }
}

}  // namespace
}  // namespace sp::io

namespace sp::io {
namespace {

TEST(TumSequenceOptions, FromYamlReadsKeysAndChecksRanges) {
  const auto r = ConfigReader::from_string(
      "prefetch: 3\nmax_frames: 10\nstart_frame: 2\ndepth_offset: -0.01\n"
      "camera_file: cam.yaml\nreader_nice: 5\n",
      "opts.yaml");
  const auto o = TumSequenceOptions::from_yaml(r);
  r.finish();
  EXPECT_EQ(o.prefetch, 3u);
  EXPECT_EQ(o.max_frames, 10u);
  EXPECT_EQ(o.start_frame, 2u);
  EXPECT_DOUBLE_EQ(o.depth_offset, -0.01);
  EXPECT_DOUBLE_EQ(o.max_difference, 0.02);  // default kept
  EXPECT_EQ(o.reader_nice, 5);
  EXPECT_EQ(TumSequenceOptions{}.reader_nice, 10);  // the measured default
  EXPECT_THROW((void)TumSequenceOptions::from_yaml(ConfigReader::from_string("reader_nice: 20\n", "o.yaml")),
               ConfigError);
  ASSERT_TRUE(o.camera_file.has_value());
  EXPECT_EQ(*o.camera_file, std::filesystem::path("cam.yaml"));
  try {
    (void)TumSequenceOptions::from_yaml(ConfigReader::from_string("a: 1\nprefetch: 0\n", "opts.yaml"));
    ADD_FAILURE() << "prefetch 0 accepted";
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.key(), "prefetch");
    EXPECT_EQ(e.line(), 2);
  }
}

}  // namespace
}  // namespace sp::io
