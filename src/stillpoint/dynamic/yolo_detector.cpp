#include "stillpoint/dynamic/yolo_detector.hpp"

#include <spdlog/spdlog.h>

#include <filesystem>
#include <optional>

#include "stillpoint/common/error.hpp"
#include "stillpoint/common/timing.hpp"
#include "stillpoint/dynamic/fast_activation.hpp"
#include "stillpoint/dynamic/fast_slice.hpp"

namespace sp::dyn {

YoloDetector::YoloDetector(const DetectorConfig& cfg) : cfg_(cfg) {
  namespace fs = std::filesystem;
  if (cfg_.model.empty()) throw ConfigError("(detector)", 0, "model", "no detector model given");
  if (!fs::exists(cfg_.model)) throw Error(cfg_.model + ": detector model file not found");
  std::string ext = fs::path(cfg_.model).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  try {
    std::optional<ScopedFastSigmoid> fast_sigmoid;
    if (cfg_.fast_sigmoid) fast_sigmoid.emplace();
    std::optional<ScopedFastSlice> fast_slice;
    if (cfg_.fast_slice) fast_slice.emplace();
    if (ext == ".cfg") {
      std::string weights =
          cfg_.weights.empty() ? fs::path(cfg_.model).replace_extension(".weights").string() : cfg_.weights;
      if (!fs::exists(weights))
        throw Error(weights + ": Darknet weights file not found (for " + cfg_.model + ")");
      net_ = cv::dnn::readNetFromDarknet(cfg_.model, weights);
      if (cfg_.decoder == "auto") cfg_.decoder = "darknet";
    } else {
      net_ = cv::dnn::readNetFromONNX(cfg_.model);
    }
  } catch (const cv::Exception& e) {
    throw Error(cfg_.model + ": cannot load the detector model: " + e.what());
  }
  if (net_.empty()) throw Error(cfg_.model + ": cannot load the detector model (empty network)");
  net_.setPreferableBackend(cv::dnn::DNN_BACKEND_OPENCV);
  net_.setPreferableTarget(cv::dnn::DNN_TARGET_CPU);
  out_names_ = net_.getUnconnectedOutLayersNames();
  if (cfg_.threads > 0) cv::setNumThreads(cfg_.threads);
  if (cfg_.decoder != "auto") decoder_ = cfg_.decoder == "yolov7" ? "yolov5" : cfg_.decoder;

  const auto& names = cfg_.names();
  keep_class_.assign(names.size(), cfg_.dynamic_classes.empty());
  for (const auto& n : cfg_.dynamic_classes) {
    const int id = class_index(names, n);
    if (id < 0) throw ConfigError("(detector)", 0, "dynamic_classes", "unknown class name '" + n + "'");
    keep_class_[static_cast<std::size_t>(id)] = true;
  }
  spdlog::info("detector: {} ({}x{}, {}, decoder {})", cfg_.model, cfg_.input_width, cfg_.input_height,
               cfg_.letterbox ? "letterbox" : "resize", cfg_.decoder);
}

Detections YoloDetector::detect(const cv::Mat& bgr) {
  Stopwatch sw;
  InputTransform tf;
  const cv::Mat blob = make_input_blob(bgr, cfg_, tf);
  net_.setInput(blob);
  std::vector<cv::Mat> outs;
  net_.forward(outs, out_names_);
  if (outs.empty()) throw Error(cfg_.model + ": network produced no output");
  if (decoder_.empty()) {
    const cv::Mat& o = outs.front();
    const int cols = o.dims >= 2 ? o.size[o.dims - 1] : o.cols;
    decoder_ = resolve_decoder(cfg_, cols > 0 ? static_cast<int>(o.total()) / cols : 0);
    spdlog::info("detector: output format '{}'", decoder_);
  }
  std::vector<Detection> raw;
  if (decoder_ == "yolox") {
    raw = decode_yolox(outs.front(), cfg_.input_width, cfg_.input_height, cfg_.conf_threshold);
  } else if (decoder_ == "yolov5") {
    raw = decode_yolov5(outs.front(), cfg_.conf_threshold);
  } else {
    raw = decode_darknet(outs, cfg_.input_width, cfg_.input_height, cfg_.conf_threshold);
  }
  std::erase_if(raw, [&](const Detection& d) {
    return d.class_id < 0 || static_cast<std::size_t>(d.class_id) >= keep_class_.size() ||
           !keep_class_[static_cast<std::size_t>(d.class_id)];
  });
  // Every box already scores >= conf_threshold, so an interior threshold at or below it drops nothing.
  std::vector<Detection> boxes = map_to_image(raw, tf);
  drop_weak_interior(boxes, bgr.size(), cfg_.interior_conf_threshold, cfg_.border_margin_px);
  Detections result;
  result.items = nms_per_class(boxes, cfg_.nms_threshold);
  result.inference_ms = sw.elapsed_ms();
  return result;
}

}  // namespace sp::dyn
