#pragma once
// Scoring of the motion check on real data, shared by test_sequences.cpp and the bound-derivation
// tool tools/motion_check_sweep.cpp: a rendered dynsynth sequence scored against its masks, and a
// fixed-camera video of pedestrians.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "stillpoint/common/timing.hpp"
#include "stillpoint/dynamic/dynamic_filter.hpp"
#include "stillpoint/dynamic/oracle_detections.hpp"
#include "stillpoint/dynamic/yolo_detector.hpp"

namespace sp::dyn::score {

namespace fs = std::filesystem;

struct Frame {
  double stamp = 0;
  std::string rgb, depth;
};

inline std::vector<Frame> read_associations(const fs::path& dir) {
  std::ifstream in(dir / "associations.txt");
  std::vector<Frame> f;
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ss(line);
    Frame fr;
    double td = 0;
    ss >> fr.stamp >> fr.rgb >> td >> fr.depth;
    f.push_back(fr);
  }
  return f;
}

// Moving instance ids per frame stamp (boxes.txt moving flag).
inline std::map<double, std::vector<int>> moving_ids(const fs::path& boxes) {
  std::map<double, std::vector<int>> m;
  std::ifstream in(boxes);
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ss(line);
    double t;
    int id, x0, y0, x1, y1, mv;
    std::string cls;
    ss >> t >> id >> cls >> x0 >> y0 >> x1 >> y1 >> mv;
    if (mv) m[t].push_back(id);
  }
  return m;
}

struct Score {
  long keypoints = 0;  // all keypoints scored
  long tp = 0, fp = 0, moving_total = 0, moving_culled = 0, any_total = 0, any_culled = 0;
  bool complete = false;  // every frame could be read
  std::vector<double> ms;
  [[nodiscard]] double precision() const { return tp + fp ? double(tp) / double(tp + fp) : 1.0; }
  [[nodiscard]] double recall_moving() const {
    return moving_total ? double(moving_culled) / moving_total : 1.0;
  }
  [[nodiscard]] double recall_any() const { return any_total ? double(any_culled) / any_total : 1.0; }
  // Precision of culling keypoints at random: the share of keypoints that lie on a person's mask.
  [[nodiscard]] double base_rate() const { return keypoints ? double(any_total) / double(keypoints) : 0.0; }
  // Recall of culling as many keypoints at random: the share of all keypoints that were culled.
  [[nodiscard]] double culled_share() const { return keypoints ? double(tp + fp) / double(keypoints) : 0.0; }
};

enum class Boxes { kOracle, kYolox, kNone };

inline const char* to_string(Boxes b) {
  return b == Boxes::kOracle ? "oracle" : b == Boxes::kYolox ? "yolox" : "none";
}

// Frames [first, last) of `seq` go through the filter (last = 0: to the end); the detector runs on
// every 3rd frame only, so its boxes arrive up to 2 frames late and are carried forward (as with the
// async detector). Oracle boxes are given on every frame.
inline Score run_sequence(const fs::path& seq, const fs::path& models, CullMode mode, Boxes boxes,
                          std::size_t first = 30, std::size_t last = 0,
                          const std::function<void(MotionCheckConfig&)>& tweak = {}) {
  Score s;
  const auto frames = read_associations(seq);
  const auto oracle = OracleDetections::load(seq / "boxes.txt");
  const auto movers = moving_ids(seq / "boxes.txt");
  std::unique_ptr<YoloDetector> yolo;
  if (boxes == Boxes::kYolox)
    yolo = std::make_unique<YoloDetector>(DetectorConfig::for_model(models / "yolox_nano.onnx"));
  MotionCheckConfig cfg;
  cfg.mode = mode;
  if (tweak) tweak(cfg);
  DynamicFeatureFilter filter(cfg);
  auto orb = cv::ORB::create(1000);
  Eigen::Matrix3d K;
  K << 535.4, 0, 320.1, 0, 539.2, 247.6, 0, 0, 1;
  cv::Mat prev_gray;
  Detections det;
  const std::size_t end = last == 0 ? frames.size() : std::min(last, frames.size());
  for (std::size_t i = first; i < end; ++i) {
    const cv::Mat bgr = cv::imread((seq / frames[i].rgb).string(), cv::IMREAD_COLOR);
    const cv::Mat d16 = cv::imread((seq / frames[i].depth).string(), cv::IMREAD_UNCHANGED);
    const cv::Mat mask =
        cv::imread((seq / "masks" / (frames[i].rgb.substr(4, frames[i].rgb.size() - 8) + ".png")).string(),
                   cv::IMREAD_UNCHANGED);
    if (bgr.empty() || d16.empty() || mask.empty()) {
      std::fprintf(stderr, "cannot read frame %zu (%s) of %s\n", i, frames[i].rgb.c_str(), seq.c_str());
      return s;
    }
    cv::Mat gray, depth;
    cv::cvtColor(bgr, gray, cv::COLOR_BGR2GRAY);
    d16.convertTo(depth, CV_32F, 1.0 / 5000.0);
    std::vector<cv::KeyPoint> kps;
    orb->detect(gray, kps);
    if (boxes == Boxes::kOracle) {
      det = oracle.at(frames[i].stamp, i);
    } else if (boxes == Boxes::kYolox && (i - first) % 3 == 0) {
      det = yolo->detect(bgr);
      det.frame_index = i;
    }
    DynamicInput in;
    in.frame_index = i;
    in.prev_gray = prev_gray.empty() ? nullptr : &prev_gray;
    in.gray = &gray;
    in.depth = &depth;
    in.keypoints = &kps;
    in.detections = boxes == Boxes::kNone ? nullptr : &det;
    in.K = K;
    const DynamicResult r = filter.process(in);
    s.ms.push_back(r.ms);
    std::vector<int> mv;
    for (const auto& [t, ids] : movers) {
      if (std::abs(t - frames[i].stamp) < 1e-4) mv = ids;
    }
    for (std::size_t k = 0; k < kps.size(); ++k) {
      const int id = mask.at<uchar>(cvRound(kps[k].pt.y), cvRound(kps[k].pt.x));
      const bool culled = r.keypoint_dynamic[k];
      const bool moving = id != 0 && std::find(mv.begin(), mv.end(), id) != mv.end();
      ++s.keypoints;
      s.tp += culled && id != 0;
      s.fp += culled && id == 0;
      s.any_total += id != 0;
      s.any_culled += culled && id != 0;
      s.moving_total += moving;
      s.moving_culled += moving && culled;
    }
    prev_gray = gray;
  }
  s.complete = true;
  const auto t = summarize(s.ms);
  std::printf(
      "[dynsynth %s/%s frames %zu-%zu] precision %.3f recall(moving) %.3f recall(any mask) %.3f base rate "
      "%.3f culled share %.3f  filter ms median %.2f p95 %.2f\n",
      to_string(mode), to_string(boxes), first, end - 1, s.precision(), s.recall_moving(), s.recall_any(),
      s.base_rate(), s.culled_share(), t.median, t.p95);
  return s;
}

struct VideoScore {
  bool opened = false;
  int frames = 0;
  int boxes = 0, dyn_boxes = 0, bg = 0, bg_moving = 0, still_boxes = 0, still_dynamic = 0;
  std::vector<double> ms;
  [[nodiscard]] double box_rate() const { return boxes ? double(dyn_boxes) / boxes : 0; }
  [[nodiscard]] double bg_static() const { return bg ? 1.0 - double(bg_moving) / bg : 0; }
};

// Frames [first, first + count) of a fixed-camera video with people: person boxes (≥ 60 px high,
// enough tracked points to be judged by motion) should be dynamic, background points static; every
// 10th frame (i % 10 == 5) is also paired with itself through a fresh filter (nothing moves).
inline VideoScore run_video(const fs::path& video, const fs::path& model, std::size_t first = 0,
                            std::size_t count = 60) {
  VideoScore v;
  cv::VideoCapture cap(video.string());
  if (!cap.isOpened()) return v;
  v.opened = true;
  YoloDetector yolo(DetectorConfig::for_model(model));
  DynamicFeatureFilter filter{MotionCheckConfig{}};
  auto orb = cv::ORB::create(1000);
  cv::Mat bgr, gray, prev;
  for (std::size_t skip = 0; skip < first && cap.read(bgr); ++skip) {
  }
  for (std::size_t i = 0; i < count && cap.read(bgr); ++i) {
    ++v.frames;
    cv::cvtColor(bgr, gray, cv::COLOR_BGR2GRAY);
    std::vector<cv::KeyPoint> kps;
    orb->detect(gray, kps);
    Detections det = yolo.detect(bgr);
    det.frame_index = i;
    DynamicInput in;
    in.frame_index = i;
    in.prev_gray = prev.empty() ? nullptr : &prev;
    in.gray = &gray;
    in.keypoints = &kps;
    in.detections = &det;
    const DynamicResult r = filter.process(in);
    if (i % 10 == 5) {  // control: the same frame twice (nothing moves) with a fresh filter
      // No class is dynamic by prior here (always_dynamic_classes empty): the control checks what the
      // motion check itself says about a frame without motion.
      MotionCheckConfig motion_only;
      motion_only.always_dynamic_classes.clear();
      DynamicFeatureFilter fresh{motion_only};
      DynamicInput still = in;
      still.prev_gray = &gray;
      const DynamicResult z = fresh.process(still);
      for (std::size_t b = 0; b < z.boxes.size(); ++b) {
        int tracked = 0;
        for (const auto& fp : z.flow_points) tracked += z.boxes[b].box.contains(fp);
        if (tracked < MotionCheckConfig{}.min_points_to_decide) continue;
        ++v.still_boxes;
        v.still_dynamic += z.box_dynamic[b];
      }
    }
    prev = gray.clone();
    if (i == 0) continue;
    v.ms.push_back(r.ms);
    for (std::size_t b = 0; b < r.boxes.size(); ++b) {
      if (r.boxes[b].box.height < 60) continue;  // far, tiny people barely move in pixels
      int tracked = 0;
      for (std::size_t p = 0; p < r.flow_points.size(); ++p)
        tracked += r.boxes[b].box.contains(r.flow_points[p]);
      if (tracked < MotionCheckConfig{}.min_points_to_decide) continue;  // judged by class, not by motion
      ++v.boxes;
      v.dyn_boxes += r.box_dynamic[b];
    }
    for (std::size_t p = 0; p < r.flow_points.size(); ++p) {
      bool in_box = false;
      for (const auto& d : r.boxes) {
        const cv::Rect2f g(d.box.x - 10, d.box.y - 10, d.box.width + 20, d.box.height + 20);
        in_box = in_box || g.contains(r.flow_points[p]);
      }
      if (in_box) continue;
      ++v.bg;
      v.bg_moving += r.flow_point_moving[p];
    }
  }
  std::printf(
      "[vtest frames %zu-%zu] person boxes %d, dynamic %.3f; background points %d, static %.3f; control "
      "boxes %d, dynamic %d; filter ms median %.2f\n",
      first, first + static_cast<std::size_t>(v.frames) - 1, v.boxes, v.box_rate(), v.bg, v.bg_static(),
      v.still_boxes, v.still_dynamic, summarize(v.ms).median);
  return v;
}

}  // namespace sp::dyn::score
