// Detector CPU timing (not a test):
//   detector_timing [--runs N] [--threads T] [--image FILE] [--input PX] [--opencv-sigmoid] [--opencv-slice]
//   MODEL...
// For each model (.onnx or Darknet .cfg, configured by DetectorConfig::for_model): 3 warm-up runs, then
// N cv::dnn forward passes alone and N full YoloDetector::detect calls (preprocess + forward + decode +
// NMS); prints median and p90 of each, with the 1-minute load average before and after (a busy machine
// makes every figure larger). --input fits a YOLOX input's long side to PX for the image (as
// dynamic.detector_input); --opencv-sigmoid times OpenCV's own Sigmoid layer instead of
// fast_sigmoid, --opencv-slice OpenCV's own Slice layer instead of the strided copy. docs/dynamic.md has the
// figures and the command.
#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <opencv2/core/utility.hpp>
#include <opencv2/dnn.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <string>
#include <vector>

#include "stillpoint/dynamic/decoders.hpp"
#include "stillpoint/dynamic/fast_activation.hpp"
#include "stillpoint/dynamic/fast_slice.hpp"
#include "stillpoint/dynamic/yolo_detector.hpp"

namespace {

double load_average() {
  std::ifstream in("/proc/loadavg");
  double l = -1;
  in >> l;
  return l;
}

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

double quantile(std::vector<double> v, double q) {
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(q * static_cast<double>(v.size() - 1) + 0.5)];
}

}  // namespace

int main(int argc, char** argv) {
  int runs = 30;
  int threads = 1;
  int input = 0;
  bool fast_sigmoid = true;
  bool fast_slice = true;
  std::string image;
  std::vector<std::string> models;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--runs" && i + 1 < argc) {
      runs = std::max(1, std::stoi(argv[++i]));
    } else if (a == "--threads" && i + 1 < argc) {
      threads = std::stoi(argv[++i]);
    } else if (a == "--input" && i + 1 < argc) {
      input = std::stoi(argv[++i]);
    } else if (a == "--opencv-sigmoid") {
      fast_sigmoid = false;
    } else if (a == "--opencv-slice") {
      fast_slice = false;
    } else if (a == "--image" && i + 1 < argc) {
      image = argv[++i];
    } else {
      models.push_back(a);
    }
  }
  if (models.empty()) {
    std::fprintf(stderr,
                 "usage: detector_timing [--runs N] [--threads T] [--image FILE] [--input PX] "
                 "[--opencv-sigmoid] [--opencv-slice] MODEL...\n");
    return 2;
  }
  cv::Mat img = image.empty() ? cv::Mat() : cv::imread(image, cv::IMREAD_COLOR);
  if (img.empty()) {  // a fixed textured 640x480 frame
    img.create(480, 640, CV_8UC3);
    cv::RNG rng(3);
    rng.fill(img, cv::RNG::UNIFORM, 0, 255);
    cv::GaussianBlur(img, img, cv::Size(9, 9), 3.0);
  }
  cv::setNumThreads(threads);
  fmt::print("image {}x{}, {} runs, {} OpenCV thread(s), cv::getNumThreads() = {}, {} sigmoid, {} slice\n",
             img.cols, img.rows, runs, threads, cv::getNumThreads(), fast_sigmoid ? "fast" : "OpenCV's",
             fast_slice ? "strided-copy" : "OpenCV's");
  fmt::print("{:<34} {:>9} {:>14} {:>14} {:>14} {:>14} {:>11}\n", "model", "input", "forward med",
             "forward p90", "detect med", "detect p90", "load 1m");
  for (const auto& m : models) {
    sp::dyn::DetectorConfig cfg = sp::dyn::DetectorConfig::for_model(m);
    cfg.threads = threads;
    cfg.fast_sigmoid = fast_sigmoid;
    cfg.fast_slice = fast_slice;
    if (input > 0 && cfg.decoder == "yolox") cfg.fit_input_to_image(input, img.cols, img.rows);
    const double load_before = load_average();
    std::optional<sp::dyn::ScopedFastSigmoid> fast_layer;
    if (fast_sigmoid) fast_layer.emplace();
    std::optional<sp::dyn::ScopedFastSlice> slice_layer;
    if (fast_slice) slice_layer.emplace();
    cv::dnn::Net net = cfg.decoder == "darknet" ? cv::dnn::readNetFromDarknet(cfg.model, cfg.weights)
                                                : cv::dnn::readNetFromONNX(cfg.model);
    fast_layer.reset();
    slice_layer.reset();
    net.setPreferableBackend(cv::dnn::DNN_BACKEND_OPENCV);
    net.setPreferableTarget(cv::dnn::DNN_TARGET_CPU);
    const auto out_names = net.getUnconnectedOutLayersNames();
    sp::dyn::InputTransform tf;
    const cv::Mat blob = sp::dyn::make_input_blob(img, cfg, tf);
    std::vector<double> forward_ms, detect_ms;
    for (int i = 0; i < runs + 3; ++i) {
      net.setInput(blob);
      std::vector<cv::Mat> outs;
      const auto t0 = std::chrono::steady_clock::now();
      net.forward(outs, out_names);
      if (i >= 3) forward_ms.push_back(ms_since(t0));
    }
    sp::dyn::YoloDetector det(cfg);
    for (int i = 0; i < runs + 3; ++i) {
      const auto t0 = std::chrono::steady_clock::now();
      (void)det.detect(img);
      if (i >= 3) detect_ms.push_back(ms_since(t0));
    }
    cv::setNumThreads(threads);  // YoloDetector sets it from cfg.threads; keep the requested value
    fmt::print("{:<34} {:>4}x{:<4} {:>11.1f} ms {:>11.1f} ms {:>11.1f} ms {:>11.1f} ms {:>4.1f}->{:<4.1f}\n",
               std::filesystem::path(m).filename().string(), cfg.input_width, cfg.input_height,
               quantile(forward_ms, 0.5), quantile(forward_ms, 0.9), quantile(detect_ms, 0.5),
               quantile(detect_ms, 0.9), load_before, load_average());
  }
  return 0;
}
