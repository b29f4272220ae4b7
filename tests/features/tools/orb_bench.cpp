// Times OrbExtractor on the frames of a TUM-layout folder: orb_bench <rgb dir> [frames] [parallel 0|1].
#include <spdlog/spdlog.h>

#include <algorithm>
#include <ctime>
#include <filesystem>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "stillpoint/common/timing.hpp"
#include "stillpoint/features/orb_extractor.hpp"

namespace {
// CPU time of this thread [ms]: unlike wall time, barely affected by other processes on the machine.
double thread_cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}
}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    spdlog::error("usage: orb_bench <rgb dir> [frames=50] [parallel=0] [opencv threads=1]");
    return 2;
  }
  const std::size_t frames = argc > 2 ? std::stoul(argv[2]) : 50;
  sp::feat::OrbConfig cfg;
  cfg.parallel_levels = argc > 3 && std::string(argv[3]) == "1";
  cv::setNumThreads(argc > 4 ? std::stoi(argv[4]) : 1);
  if (argc > 5) cfg.fast_min_threshold = std::stoi(argv[5]);
  std::vector<std::filesystem::path> files;
  for (const auto& e : std::filesystem::directory_iterator(argv[1])) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  files.resize(std::min(files.size(), frames));
  std::vector<cv::Mat> images;
  for (const auto& f : files) images.push_back(cv::imread(f.string(), cv::IMREAD_GRAYSCALE));

  sp::feat::OrbExtractor orb(cfg);
  std::vector<cv::KeyPoint> kps;
  cv::Mat desc;
  orb.extract(images.front(), kps, desc);  // warm-up: allocates the pyramid buffers
  std::vector<double> ms, cpu, counts;
  for (const cv::Mat& img : images) {
    sp::Stopwatch sw;
    const double c0 = thread_cpu_ms();
    orb.extract(img, kps, desc);
    cpu.push_back(thread_cpu_ms() - c0);
    ms.push_back(sw.elapsed_ms());
    counts.push_back(static_cast<double>(kps.size()));
  }
  const auto t = sp::summarize(ms);
  const auto c = sp::summarize(counts);
  const auto u = sp::summarize(cpu);
  spdlog::info(
      "{} frames, parallel_levels={}, cv threads={}: median {:.2f} ms, mean {:.2f}, p95 {:.2f}, "
      "min {:.2f}; this thread's CPU time median {:.2f} ms; keypoints median {:.0f} (min {:.0f})",
      t.count, cfg.parallel_levels, cv::getNumThreads(), t.median, t.mean, t.p95,
      *std::min_element(ms.begin(), ms.end()), u.median, c.median,
      *std::min_element(counts.begin(), counts.end()));
  return 0;
}
