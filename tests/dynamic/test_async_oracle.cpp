// AsyncDetector lifecycle and the oracle boxes reader.
#include <gtest/gtest.h>

#include <atomic>
#include <filesystem>
#include <fstream>
#include <thread>

#include "stillpoint/common/error.hpp"
#include "stillpoint/dynamic/async_detector.hpp"
#include "stillpoint/dynamic/oracle_detections.hpp"

namespace sp::dyn {
namespace {

using namespace std::chrono_literals;

// A fake detector: one box whose x is the image's first pixel value, after a delay.
struct SlowFake {
  std::chrono::milliseconds delay;
  std::shared_ptr<std::atomic<int>> calls = std::make_shared<std::atomic<int>>(0);
  Detections operator()(const cv::Mat& img) const {
    std::this_thread::sleep_for(delay);
    ++*calls;
    Detections d;
    d.items.push_back({cv::Rect2f(img.at<uchar>(0, 0), 0, 10, 10), 0, 1.f});
    return d;
  }
};

cv::Mat frame(int v) { return cv::Mat(4, 4, CV_8U, cv::Scalar(v)); }

TEST(AsyncDetector, SyncModeDetectsInTheCallersThread) {
  SlowFake fake{0ms};
  AsyncDetector a(fake, AsyncDetector::Mode::kSync);
  EXPECT_FALSE(a.latest().has_value());
  a.submit(7, 1.5, frame(42));
  const auto d = a.latest();
  ASSERT_TRUE(d.has_value());
  EXPECT_EQ(d->frame_index, 7u);
  EXPECT_DOUBLE_EQ(d->stamp, 1.5);
  EXPECT_FLOAT_EQ(d->items.at(0).box.x, 42.f);
  EXPECT_EQ(*fake.calls, 1);
}

TEST(AsyncDetector, SyncLatencyShowsEachDetectionThatManyFramesLateWithoutWaiting) {
  SlowFake fake{0ms};
  AsyncDetector a(fake, AsyncDetector::Mode::kSync);
  a.set_sync_latency(4);
  const auto t0 = std::chrono::steady_clock::now();
  // Detect every 3rd frame, as the system does; query every frame with the stale-wait rule on.
  for (std::size_t f = 0; f < 20; ++f) {
    if (f % 3 == 0) a.submit(f, static_cast<double>(f), frame(static_cast<int>(f)));
    const auto fresh = a.wait_for_fresh(f, 50ms, 2, 200ms);
    // Newest detection whose frame is at least 4 back: frame f - 4 rounded down to a multiple of 3.
    if (f < 4) {
      EXPECT_FALSE(fresh.detections.has_value()) << "frame " << f;
    } else {
      ASSERT_TRUE(fresh.detections.has_value()) << "frame " << f;
      EXPECT_EQ(fresh.detections->frame_index, (f - 4) / 3 * 3) << "frame " << f;
    }
  }
  // Nothing ran in the background, so neither the budget nor the stale wait was spent waiting.
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 500ms);
  EXPECT_EQ(*fake.calls, 7);
}

TEST(AsyncDetector, WaitForGetsTheFrameAndKeepsOnlyTheNewestPending) {
  SlowFake fake{30ms};
  AsyncDetector a(fake, AsyncDetector::Mode::kAsync);
  a.submit(0, 0.0, frame(0));
  const auto d0 = a.wait_for(0, 5s);
  ASSERT_TRUE(d0.has_value());
  EXPECT_EQ(d0->frame_index, 0u);
  // Burst while busy: only the newest pending frame survives.
  for (int i = 1; i <= 6; ++i) a.submit(static_cast<std::size_t>(i), i, frame(i));
  const auto d6 = a.wait_for(6, 5s);
  ASSERT_TRUE(d6.has_value());
  EXPECT_EQ(d6->frame_index, 6u);
  EXPECT_FLOAT_EQ(d6->items.at(0).box.x, 6.f);  // the image was copied at submit
  EXPECT_GE(a.dropped(), 4u);
  EXPECT_LE(*fake.calls, 3);
  a.stop();
}

TEST(AsyncDetector, WaitForReturnsTheLatestWhenTheBudgetRunsOut) {
  SlowFake fake{300ms};
  AsyncDetector a(fake, AsyncDetector::Mode::kAsync);
  a.submit(0, 0.0, frame(1));
  ASSERT_TRUE(a.wait_for(0, 10s).has_value());
  a.submit(1, 1.0, frame(2));
  const auto d = a.wait_for(1, 1ms);  // far below the detector's time
  ASSERT_TRUE(d.has_value());
  EXPECT_EQ(d->frame_index, 0u);
}

// A detector slower than the frame rate falls behind; with a maximum age the caller waits until a
// detection at most that old exists, without one it takes whatever is newest at once.
TEST(AsyncDetector, WaitForFreshBoundsTheAgeOfTheDetectionUsed) {
  SlowFake fake{200ms};  // long, so a loaded test machine does not reorder the steps below
  AsyncDetector a(fake, AsyncDetector::Mode::kAsync);
  a.submit(0, 0.0, frame(0));
  ASSERT_TRUE(a.wait_for(0, 5s).has_value());
  // Frames 3 and 6 submitted back to back: the worker is busy with 3 when frame 9 asks.
  a.submit(3, 3.0, frame(3));
  std::this_thread::sleep_for(5ms);
  a.submit(6, 6.0, frame(6));
  const auto quick = a.wait_for_fresh(9, 0ms, 0, 5s);
  ASSERT_TRUE(quick.detections.has_value());
  EXPECT_LT(quick.detections->frame_index, 5u) << "no maximum age: the newest finished one, at once";
  EXPECT_EQ(quick.stale_wait_ms, 0.0);
  const auto fresh = a.wait_for_fresh(9, 0ms, 4, 5s);
  ASSERT_TRUE(fresh.detections.has_value());
  EXPECT_GE(fresh.detections->frame_index, 5u) << "at most 4 frames older than frame 9";
  EXPECT_GT(fresh.stale_wait_ms, 10.0) << "it had to wait for the worker";
  // Fresh enough already: no second wait.
  const auto again = a.wait_for_fresh(9, 0ms, 4, 5s);
  EXPECT_EQ(again.stale_wait_ms, 0.0);
  // A bounded wait returns the newest available when the worker cannot deliver in time.
  a.submit(30, 30.0, frame(30));
  const auto bounded = a.wait_for_fresh(40, 0ms, 2, 1ms);
  ASSERT_TRUE(bounded.detections.has_value());
  EXPECT_LT(bounded.detections->frame_index, 38u);
  EXPECT_LT(bounded.stale_wait_ms, 150.0);
}

// The first frames: without wait_first they go on with no boxes while the first detection runs (the
// map would start on the people in view); with it they wait for that detection.
TEST(AsyncDetector, WaitForFreshWaitsForTheFirstDetectionOnlyWhenAsked) {
  SlowFake fake{200ms};
  AsyncDetector a(fake, AsyncDetector::Mode::kAsync);
  a.submit(0, 0.0, frame(0));
  const auto early = a.wait_for_fresh(1, 0ms, 4, 5s);
  EXPECT_FALSE(early.detections.has_value()) << "frame 1 of 4 allowed: no wait, no boxes yet";
  EXPECT_EQ(early.stale_wait_ms, 0.0);
  const auto waited = a.wait_for_fresh(2, 0ms, 4, 5s, /*wait_first=*/true);
  ASSERT_TRUE(waited.detections.has_value());
  EXPECT_EQ(waited.detections->frame_index, 0u);
  EXPECT_GT(waited.stale_wait_ms, 10.0) << "it had to wait for the worker";
  // Once a detection exists, the first frames take it as fresh enough.
  const auto after = a.wait_for_fresh(3, 0ms, 4, 5s, /*wait_first=*/true);
  EXPECT_EQ(after.stale_wait_ms, 0.0);
}

TEST(AsyncDetector, StopMidRunFinishesCleanlyAndIgnoresLaterFrames) {
  SlowFake fake{100ms};
  auto a = std::make_unique<AsyncDetector>(fake, AsyncDetector::Mode::kAsync);
  a->submit(0, 0.0, frame(1));
  a->submit(1, 0.0, frame(2));
  std::this_thread::sleep_for(20ms);
  a->stop();  // joins after the detection in progress
  const int calls = *fake.calls;
  EXPECT_LE(calls, 1);
  a->submit(2, 0.0, frame(3));
  a->stop();  // idempotent
  EXPECT_EQ(*fake.calls, calls);
  EXPECT_FALSE(a->wait_for(5, 1ms).has_value() && a->latest()->frame_index == 2u);
  a.reset();  // destructor after stop
}

TEST(AsyncDetector, DetectorErrorIsRethrownToTheCaller) {
  AsyncDetector a([](const cv::Mat&) -> Detections { throw Error("boom"); }, AsyncDetector::Mode::kAsync);
  a.submit(0, 0.0, frame(1));
  // Whether the worker has failed before the call or fails during the wait, the wait rethrows it.
  EXPECT_THROW(a.wait_for(0, 10s), Error);
  // Rethrown once: the next frames go on (and fail again, which the next call reports).
  a.submit(1, 0.0, frame(1));
  EXPECT_THROW(a.wait_for(1, 10s), Error);
}

TEST(AsyncDetector, ModelLoadErrorThrowsInTheCallersThread) {
  DetectorConfig cfg;
  cfg.model = "/nonexistent/yolo.onnx";
  EXPECT_THROW(AsyncDetector(cfg, AsyncDetector::Mode::kAsync), Error);
}

std::filesystem::path write_file(const std::string& name, const std::string& text) {
  std::filesystem::create_directories(SP_TEST_TMP_DIR);
  const auto p = std::filesystem::path(SP_TEST_TMP_DIR) / name;
  std::ofstream(p) << text;
  return p;
}

TEST(OracleDetections, NearestStampMovingBoxes) {
  const auto p = write_file("boxes_ok.txt",
                            "# header\n"
                            "1.000 1 person 10 20 29 59 1\n"
                            "1.000 2 person 100 100 109 109 0\n"
                            "1.033 1 person 12 20 31 59 1\n");
  const auto o = OracleDetections::load(p);
  EXPECT_EQ(o.frame_count(), 2u);
  const Detections d = o.at(1.005, 3);
  EXPECT_EQ(d.frame_index, 3u);
  ASSERT_EQ(d.items.size(), 1u);  // the standing person is left out
  EXPECT_FLOAT_EQ(d.items[0].box.x, 10.f);
  EXPECT_FLOAT_EQ(d.items[0].box.width, 20.f);  // inclusive bounds
  EXPECT_EQ(d.items[0].class_id, 0);
  EXPECT_EQ(o.at(1.0, 0, false).items.size(), 2u);
  EXPECT_FLOAT_EQ(o.at(1.030).items.at(0).box.x, 12.f);
  EXPECT_TRUE(o.at(2.0).items.empty());  // no frame near
}

TEST(OracleDetections, MalformedLinesNameFileAndLine) {
  const char* bad[] = {"1.0 1 person 10 20 30\n", "1.0 1 person 10 20 30 40 2\n",
                       "1.0 1 person 50 20 30 40 1\n", "1.0 1 person 10 20 30 40 1 extra\n"};
  int k = 0;
  for (const char* line : bad) {
    const auto p = write_file("boxes_bad" + std::to_string(k++) + ".txt", std::string("# c\n") + line);
    try {
      OracleDetections::load(p);
      FAIL() << "accepted: " << line;
    } catch (const InputError& e) {
      EXPECT_EQ(e.line(), 2);
      EXPECT_NE(std::string(e.what()).find(p.string() + ":2"), std::string::npos);
    }
  }
  EXPECT_THROW(OracleDetections::load("/nonexistent/boxes.txt"), Error);
}

}  // namespace
}  // namespace sp::dyn
