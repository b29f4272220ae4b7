// Times DynamicFeatureFilter::process() on a dynsynth sequence with its oracle boxes (not a test: it
// prints figures and checks nothing). cv::setNumThreads(1) keeps all work in this thread, so its CPU
// time is not inflated by other jobs sharing the cores (wall time is).
//   motion_check_timing <sequence dir with associations.txt and boxes.txt> [first frame=40]
#include <spdlog/spdlog.h>

#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <opencv2/core/utility.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "../sequence_score.hpp"
#include "stillpoint/common/timing.hpp"
#include "stillpoint/dynamic/dynamic_filter.hpp"
#include "stillpoint/dynamic/oracle_detections.hpp"

namespace {

namespace fs = std::filesystem;

using sp::dyn::score::read_associations;

double thread_cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace sp::dyn;
  if (argc < 2) {
    spdlog::error("usage: motion_check_timing <dynsynth sequence dir> [first frame=40]");
    return 2;
  }
  const fs::path seq = argv[1];
  const std::size_t first = argc > 2 ? std::stoul(argv[2]) : 40;
  const auto frames = read_associations(seq);
  if (frames.size() <= first + 1) {
    spdlog::error("{}: no associations.txt or fewer than {} frames", seq.string(), first + 2);
    return 1;
  }
  cv::setNumThreads(1);
  const auto oracle = OracleDetections::load(seq / "boxes.txt");
  DynamicFeatureFilter filter{MotionCheckConfig{}};
  auto orb = cv::ORB::create(1000);
  Eigen::Matrix3d K;
  K << 535.4, 0, 320.1, 0, 539.2, 247.6, 0, 0, 1;
  cv::Mat prev;
  std::vector<double> cpu, wall;
  for (std::size_t i = first; i < frames.size(); ++i) {
    cv::Mat gray = cv::imread((seq / frames[i].rgb).string(), cv::IMREAD_GRAYSCALE), depth;
    const cv::Mat d16 = cv::imread((seq / frames[i].depth).string(), cv::IMREAD_UNCHANGED);
    if (gray.empty() || d16.empty()) {
      spdlog::error("cannot read frame {} of {}", i, seq.string());
      return 1;
    }
    d16.convertTo(depth, CV_32F, 1.0 / 5000);
    std::vector<cv::KeyPoint> kps;
    orb->detect(gray, kps);
    const Detections det = oracle.at(frames[i].stamp, i);
    DynamicInput in;
    in.frame_index = i;
    in.prev_gray = prev.empty() ? nullptr : &prev;
    in.gray = &gray;
    in.depth = &depth;
    in.keypoints = &kps;
    in.detections = &det;
    in.K = K;
    const double a = thread_cpu_ms();
    const DynamicResult r = filter.process(in);
    const double b = thread_cpu_ms();
    if (!prev.empty()) {
      cpu.push_back(b - a);
      wall.push_back(r.ms);
    }
    prev = gray;
  }
  const auto c = sp::summarize(cpu), w = sp::summarize(wall);
  std::printf(
      "[timing] motion check 640x480, %zu frames, 1 OpenCV thread: CPU median %.2f p95 %.2f ms; wall median "
      "%.2f ms\n",
      c.count, c.median, c.p95, w.median);
  return 0;
}
