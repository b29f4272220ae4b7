#pragma once
// Two detector configurations run on the same people photos must report the same boxes: for layers
// swapped in for speed (fast_activation, fast_slice), whose outputs must not change the detections.
#include <gtest/gtest.h>

#include <filesystem>
#include <initializer_list>
#include <opencv2/imgcodecs.hpp>

#include "stillpoint/dynamic/yolo_detector.hpp"

namespace sp::dyn::testing {

// YOLOX-nano as the system runs it on a 640x480 camera (320x256 input), every fast layer on.
inline DetectorConfig yolox_nano_as_run(const std::filesystem::path& model) {
  DetectorConfig c = DetectorConfig::for_model(model);
  c.fit_input_to_image(320, 640, 480);
  return c;
}

// Boxes within box_tol px and scores within score_tol (0: equal); returns how many boxes were compared.
inline int compare_detections(const DetectorConfig& a_cfg, const DetectorConfig& b_cfg,
                              const std::filesystem::path& folder, std::initializer_list<const char*> files,
                              double box_tol, double score_tol) {
  YoloDetector det_a(a_cfg), det_b(b_cfg);
  int boxes = 0;
  for (const char* file : files) {
    const cv::Mat img = cv::imread((folder / file).string(), cv::IMREAD_COLOR);
    EXPECT_FALSE(img.empty()) << file;
    if (img.empty()) continue;
    const Detections a = det_a.detect(img), b = det_b.detect(img);
    EXPECT_EQ(a.items.size(), b.items.size()) << file;
    if (a.items.size() != b.items.size()) continue;
    for (std::size_t i = 0; i < a.items.size(); ++i) {
      EXPECT_NEAR(a.items[i].box.x, b.items[i].box.x, box_tol) << file;
      EXPECT_NEAR(a.items[i].box.y, b.items[i].box.y, box_tol) << file;
      EXPECT_NEAR(a.items[i].box.width, b.items[i].box.width, box_tol) << file;
      EXPECT_NEAR(a.items[i].box.height, b.items[i].box.height, box_tol) << file;
      EXPECT_NEAR(a.items[i].score, b.items[i].score, score_tol) << file;
    }
    boxes += static_cast<int>(a.items.size());
  }
  return boxes;
}

}  // namespace sp::dyn::testing
