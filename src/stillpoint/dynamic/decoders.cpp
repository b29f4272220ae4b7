#include "stillpoint/dynamic/decoders.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <opencv2/dnn.hpp>
#include <opencv2/imgproc.hpp>

#include "stillpoint/common/error.hpp"

namespace sp::dyn {

namespace {

// Views a network output as rows x cols (cols = its last dimension); no copy for continuous Mats.
cv::Mat as_rows(const cv::Mat& out) {
  if (out.empty()) return {};
  if (out.type() != CV_32F)
    throw Error("detector output: expected CV_32F, got type " + std::to_string(out.type()));
  const int cols = out.dims >= 2 ? out.size[out.dims - 1] : out.cols;
  const auto total = static_cast<int>(out.total());
  if (cols <= 5 || total % cols != 0)
    throw Error("detector output: last dimension " + std::to_string(cols) + " is not 5 + classes");
  cv::Mat m = out.isContinuous() ? out : out.clone();
  return m.reshape(1, total / cols);
}

// Best class and its score of one row (class scores start at column 5).
std::pair<int, float> best_class(const float* row, int num_classes) {
  const float* cls = row + 5;
  const auto it = std::max_element(cls, cls + num_classes);
  return {static_cast<int>(it - cls), *it};
}

int yolox_grid_count(int w, int h, const std::vector<int>& strides) {
  int n = 0;
  for (int s : strides) n += (w / s) * (h / s);
  return n;
}

}  // namespace

cv::Mat make_input_blob(const cv::Mat& bgr, const DetectorConfig& cfg, InputTransform& tf) {
  if (bgr.empty()) throw Error("detector: empty image");
  cv::Mat img = bgr;
  if (img.channels() == 1) cv::cvtColor(bgr, img, cv::COLOR_GRAY2BGR);
  if (img.depth() != CV_8U) throw Error("detector: expected an 8-bit image");
  tf.image_width = img.cols;
  tf.image_height = img.rows;
  const int W = cfg.input_width, H = cfg.input_height;
  cv::Mat net_img;
  if (cfg.letterbox) {
    const double r = std::min(static_cast<double>(W) / img.cols, static_cast<double>(H) / img.rows);
    const int rw = std::max(1, static_cast<int>(std::lround(img.cols * r)));
    const int rh = std::max(1, static_cast<int>(std::lround(img.rows * r)));
    net_img = cv::Mat(H, W, CV_8UC3, cv::Scalar(114, 114, 114));
    cv::Mat resized;
    cv::resize(img, resized, cv::Size(std::min(rw, W), std::min(rh, H)), 0, 0, cv::INTER_LINEAR);
    resized.copyTo(net_img(cv::Rect(0, 0, resized.cols, resized.rows)));
    tf.sx = tf.sy = r;
  } else {
    cv::resize(img, net_img, cv::Size(W, H), 0, 0, cv::INTER_LINEAR);
    tf.sx = static_cast<double>(W) / img.cols;
    tf.sy = static_cast<double>(H) / img.rows;
  }
  return cv::dnn::blobFromImage(net_img, cfg.scale, cv::Size(), cv::Scalar(), cfg.swap_rb, false, CV_32F);
}

std::vector<Detection> decode_yolov5(const cv::Mat& out, float conf_threshold) {
  std::vector<Detection> dets;
  const cv::Mat m = as_rows(out);
  const int nc = m.cols - 5;
  for (int i = 0; i < m.rows; ++i) {
    const float* row = m.ptr<float>(i);
    const float obj = row[4];
    if (obj < conf_threshold) continue;  // score = obj * cls <= obj
    const auto [cls, cls_score] = best_class(row, nc);
    const float score = obj * cls_score;
    if (score < conf_threshold) continue;
    dets.push_back({cv::Rect2f(row[0] - row[2] / 2, row[1] - row[3] / 2, row[2], row[3]), cls, score});
  }
  return dets;
}

std::vector<Detection> decode_yolox(const cv::Mat& out, int input_width, int input_height,
                                    float conf_threshold, const std::vector<int>& strides) {
  std::vector<Detection> dets;
  const cv::Mat m = as_rows(out);
  const int expected = yolox_grid_count(input_width, input_height, strides);
  if (m.rows != expected) {
    throw Error("YOLOX output has " + std::to_string(m.rows) + " rows, the grids of a " +
                std::to_string(input_width) + "x" + std::to_string(input_height) + " input have " +
                std::to_string(expected) + " (wrong input size or not a YOLOX raw head?)");
  }
  const int nc = m.cols - 5;
  int i = 0;
  for (int s : strides) {
    const int gw = input_width / s, gh = input_height / s;
    for (int gy = 0; gy < gh; ++gy) {
      for (int gx = 0; gx < gw; ++gx, ++i) {
        const float* row = m.ptr<float>(i);
        if (row[4] < conf_threshold) continue;
        const auto [cls, cls_score] = best_class(row, nc);
        const float score = row[4] * cls_score;
        if (score < conf_threshold) continue;
        const float cx = (row[0] + static_cast<float>(gx)) * static_cast<float>(s);
        const float cy = (row[1] + static_cast<float>(gy)) * static_cast<float>(s);
        const float w = std::exp(row[2]) * static_cast<float>(s);
        const float h = std::exp(row[3]) * static_cast<float>(s);
        dets.push_back({cv::Rect2f(cx - w / 2, cy - h / 2, w, h), cls, score});
      }
    }
  }
  return dets;
}

std::vector<Detection> decode_darknet(const std::vector<cv::Mat>& outs, int input_width, int input_height,
                                      float conf_threshold) {
  std::vector<Detection> dets;
  const auto W = static_cast<float>(input_width), H = static_cast<float>(input_height);
  for (const cv::Mat& out : outs) {
    const cv::Mat m = as_rows(out);
    const int nc = m.cols - 5;
    for (int i = 0; i < m.rows; ++i) {
      const float* row = m.ptr<float>(i);
      const auto [cls, score] = best_class(row, nc);
      if (score < conf_threshold) continue;
      const float w = row[2] * W, h = row[3] * H;
      dets.push_back({cv::Rect2f(row[0] * W - w / 2, row[1] * H - h / 2, w, h), cls, score});
    }
  }
  return dets;
}

std::vector<Detection> map_to_image(const std::vector<Detection>& dets, const InputTransform& tf) {
  std::vector<Detection> outv;
  outv.reserve(dets.size());
  const cv::Rect2f image(0.f, 0.f, static_cast<float>(tf.image_width), static_cast<float>(tf.image_height));
  for (Detection d : dets) {
    const auto sx = static_cast<float>(tf.sx), sy = static_cast<float>(tf.sy);
    d.box = cv::Rect2f(d.box.x / sx, d.box.y / sy, d.box.width / sx, d.box.height / sy) & image;
    if (d.box.width > 0.f && d.box.height > 0.f) outv.push_back(d);
  }
  return outv;
}

float iou(const cv::Rect2f& a, const cv::Rect2f& b) {
  const float inter = (a & b).area();
  const float uni = a.area() + b.area() - inter;
  return uni > 0.f ? inter / uni : 0.f;
}

bool reaches_border(const cv::Rect2f& box, cv::Size image, float margin_px) {
  return box.x <= margin_px || box.y <= margin_px ||
         box.x + box.width >= static_cast<float>(image.width) - margin_px ||
         box.y + box.height >= static_cast<float>(image.height) - margin_px;
}

void drop_weak_interior(std::vector<Detection>& dets, cv::Size image, float min_interior_score,
                        float margin_px) {
  std::erase_if(dets, [&](const Detection& d) {
    return d.score < min_interior_score && !reaches_border(d.box, image, margin_px);
  });
}

std::vector<Detection> nms_per_class(std::vector<Detection> dets, float iou_threshold) {
  std::stable_sort(dets.begin(), dets.end(),
                   [](const Detection& a, const Detection& b) { return a.score > b.score; });
  std::vector<Detection> kept;
  for (const Detection& d : dets) {
    const bool suppressed = std::any_of(kept.begin(), kept.end(), [&](const Detection& k) {
      return k.class_id == d.class_id && iou(k.box, d.box) > iou_threshold;
    });
    if (!suppressed) kept.push_back(d);
  }
  return kept;
}

std::string resolve_decoder(const DetectorConfig& cfg, int output_rows) {
  if (cfg.decoder != "auto") return cfg.decoder == "yolov7" ? "yolov5" : cfg.decoder;
  std::string ext = std::filesystem::path(cfg.model).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  if (ext == ".cfg" || ext == ".weights") return "darknet";
  const int grid = yolox_grid_count(cfg.input_width, cfg.input_height, {8, 16, 32});
  if (output_rows == grid) return "yolox";
  if (output_rows == 3 * grid) return "yolov5";
  throw Error(cfg.model + ": cannot tell the output format from " + std::to_string(output_rows) +
              " rows at input " + std::to_string(cfg.input_width) + "x" + std::to_string(cfg.input_height) +
              "; set decoder: yolov5|yolov7|yolox|darknet");
}

}  // namespace sp::dyn
