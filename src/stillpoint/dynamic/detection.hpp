#pragma once
// Detector output types and the detector configuration (shared by the YOLO loader, the async
// wrapper, the oracle and the motion check).
#include <cstddef>
#include <filesystem>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "stillpoint/common/config_reader.hpp"

namespace sp::dyn {

// One object in original-image pixels (box clipped to the image).
struct Detection {
  cv::Rect2f box;
  int class_id = 0;
  float score = 0.f;
};

// All objects found in one frame. `frame_index`/`stamp` name the frame the boxes belong to.
struct Detections {
  std::size_t frame_index = 0;
  double stamp = 0;
  std::vector<Detection> items;
  double inference_ms = 0;  // detector wall time (preprocess + forward + decode)
};

// The 80 COCO class names (line = class id), the default class table.
const std::vector<std::string>& coco_class_names();

// Index of `name` in `names`, or -1.
int class_index(const std::vector<std::string>& names, const std::string& name);

struct DetectorConfig {
  std::string model;             // .onnx or Darknet .cfg
  std::string weights;           // Darknet weights; empty = same stem as the .cfg with .weights
  std::string decoder = "auto";  // yolov5 | yolov7 | yolox | darknet | auto (file type / output shape)
  int input_width = 416;         // network input, px [32, 4096]
  int input_height = 416;
  bool letterbox = true;  // true: resize by r = min(W/w, H/h), paste top-left, pad 114; false: plain resize
  bool swap_rb = false;   // true: feed RGB (the image comes in as BGR)
  double scale = 1.0;     // pixel scale factor (1/255 for Darknet and YOLOv5/v7 exports)
  float conf_threshold = 0.35f;  // final score (objectness x class) threshold [0, 1]
  // Boxes that do not reach the image border need at least this score (0 or <= conf_threshold: no
  // difference). People cut by the image edge score lower than people in full view, so a low
  // conf_threshold with a higher interior one keeps the cut ones without more false boxes inside.
  float interior_conf_threshold = 0.f;  // [0, 1]
  // A box within this many pixels of an image edge reaches the border [0, 1000].
  float border_margin_px = 4.f;
  float nms_threshold = 0.45f;                            // class-aware NMS IoU threshold [0, 1]
  std::vector<std::string> class_names;                   // empty = COCO 80 built in
  std::vector<std::string> dynamic_classes = {"person"};  // only these are reported; empty = all classes
  // OpenCV worker threads for the forward pass. cv::setNumThreads is process-wide, so the default 0
  // leaves OpenCV's setting alone; > 0 sets it when the detector is built.
  int threads = 0;
  // The network's Sigmoid layers use fast_sigmoid (dynamic/fast_activation.hpp: vectorised, relative
  // error < 2e-7; YOLOX-nano forward 32 vs 40 ms, docs/dynamic.md); false = OpenCV's own layer.
  bool fast_sigmoid = true;
  // The network's Slice layers copy by strides (dynamic/fast_slice.hpp; same output; YOLOX-nano's
  // input slicing ~5 ms -> < 1 ms, docs/dynamic.md); false = OpenCV's own layer.
  bool fast_slice = true;

  // Keys as the field names; `model` is resolved relative to the YAML file's folder.
  static DetectorConfig from_yaml(const ConfigReader& r);
  // A sensible configuration from a model path alone (see docs/dynamic.md):
  //   *.cfg        -> darknet, width/height from the cfg's [net], RGB, 1/255, plain resize;
  //   *yolox*.onnx -> yolox, 416, BGR 0-255, letterbox;
  //   other .onnx  -> yolov7 layout (1xNx85 decoded), 640, RGB, 1/255, letterbox.
  // Throws sp::Error naming the file when it does not exist or the extension is unknown.
  static DetectorConfig for_model(const std::filesystem::path& model);

  // Sets the network input for images of image_width x image_height: the long side `long_side` px,
  // the short side following the image's aspect, each rounded up to a multiple of 32 (the largest
  // stride), e.g. 640x480 at 320 -> 320x256. Only for models whose grid is decoded outside the graph
  // (YOLOX): exports that bake the grid into the graph (YOLOv7 with grid) need their own size.
  void fit_input_to_image(int long_side, int image_width, int image_height);

  // The class table in use (class_names or COCO).
  [[nodiscard]] const std::vector<std::string>& names() const {
    return class_names.empty() ? coco_class_names() : class_names;
  }
};

}  // namespace sp::dyn
