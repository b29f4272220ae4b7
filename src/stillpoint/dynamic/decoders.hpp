#pragma once
// Pure functions between an image and a YOLO network: preprocessing geometry, the output decoders
// of the supported export formats, mapping back to the image, and class-aware NMS. Decoders return
// boxes in network-input pixels, before NMS, with score >= conf_threshold.
#include <opencv2/core.hpp>
#include <vector>

#include "stillpoint/dynamic/detection.hpp"

namespace sp::dyn {

// Maps network-input pixels to image pixels: x_img = x_net / sx, y_img = y_net / sy.
// Letterbox: sx = sy = r (content pasted at the top-left); plain resize: sx = W/w, sy = H/h.
struct InputTransform {
  double sx = 1.0, sy = 1.0;
  int image_width = 0, image_height = 0;
};

// Builds the network input (NCHW float blob) and the transform back to the image.
cv::Mat make_input_blob(const cv::Mat& bgr, const DetectorConfig& cfg, InputTransform& tf);

// (a) YOLOv5 / YOLOv7 export with decoding inside the graph: rows (cx, cy, w, h in input px,
// objectness, C class scores). `out` is any float Mat whose last dimension is 5 + C.
std::vector<Detection> decode_yolov5(const cv::Mat& out, float conf_threshold);

// (b) YOLOX raw head: rows (x, y, w, h raw, objectness, C class scores), one row per grid cell for
// each stride (row-major, smallest stride first): cx = (x + gx) * s, w = exp(w) * s.
// Throws sp::Error when the row count does not match the grids of the input size.
std::vector<Detection> decode_yolox(const cv::Mat& out, int input_width, int input_height,
                                    float conf_threshold, const std::vector<int>& strides = {8, 16, 32});

// (c) Darknet region/YOLO layers as cv::dnn returns them: rows (cx, cy, w, h normalised to 0-1,
// objectness, C class scores). cv::dnn already multiplies the class scores by the objectness, so
// the score is the class score.
std::vector<Detection> decode_darknet(const std::vector<cv::Mat>& outs, int input_width, int input_height,
                                      float conf_threshold);

// Network pixels -> image pixels, clipped to the image; boxes left with no area are dropped.
std::vector<Detection> map_to_image(const std::vector<Detection>& dets, const InputTransform& tf);

// Greedy NMS within each class (cv::dnn::NMSBoxesBatched does not exist in OpenCV 4.6).
// Result sorted by descending score.
std::vector<Detection> nms_per_class(std::vector<Detection> dets, float iou_threshold);

float iou(const cv::Rect2f& a, const cv::Rect2f& b);

// True when the box comes within margin_px of an edge of an image of the given size.
bool reaches_border(const cv::Rect2f& box, cv::Size image, float margin_px);

// Drops boxes (image pixels) that score below min_interior_score and do not reach the image border.
void drop_weak_interior(std::vector<Detection>& dets, cv::Size image, float min_interior_score,
                        float margin_px);

// "auto" resolved from the model file type and the output shape (rows x cols of the first output).
// yolox when rows equal the YOLOX grid count, yolov5 when rows are 3x that (3 anchors per cell).
std::string resolve_decoder(const DetectorConfig& cfg, int output_rows);

}  // namespace sp::dyn
