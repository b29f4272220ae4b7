#include "stillpoint/dynamic/detection.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <string>
#include <system_error>

#include "stillpoint/common/error.hpp"

namespace sp::dyn {

const std::vector<std::string>& coco_class_names() {
  static const std::vector<std::string> names = {
      "person",        "bicycle",    "car",           "motorbike",     "aeroplane",    "bus",
      "train",         "truck",      "boat",          "traffic light", "fire hydrant", "stop sign",
      "parking meter", "bench",      "bird",          "cat",           "dog",          "horse",
      "sheep",         "cow",        "elephant",      "bear",          "zebra",        "giraffe",
      "backpack",      "umbrella",   "handbag",       "tie",           "suitcase",     "frisbee",
      "skis",          "snowboard",  "sports ball",   "kite",          "baseball bat", "baseball glove",
      "skateboard",    "surfboard",  "tennis racket", "bottle",        "wine glass",   "cup",
      "fork",          "knife",      "spoon",         "bowl",          "banana",       "apple",
      "sandwich",      "orange",     "broccoli",      "carrot",        "hot dog",      "pizza",
      "donut",         "cake",       "chair",         "sofa",          "pottedplant",  "bed",
      "diningtable",   "toilet",     "tvmonitor",     "laptop",        "mouse",        "remote",
      "keyboard",      "cell phone", "microwave",     "oven",          "toaster",      "sink",
      "refrigerator",  "book",       "clock",         "vase",          "scissors",     "teddy bear",
      "hair drier",    "toothbrush"};
  return names;
}

int class_index(const std::vector<std::string>& names, const std::string& name) {
  const auto it = std::find(names.begin(), names.end(), name);
  return it == names.end() ? -1 : static_cast<int>(it - names.begin());
}

namespace {

std::string lower_ext(const std::filesystem::path& p) {
  std::string e = p.extension().string();
  std::transform(e.begin(), e.end(), e.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return e;
}

// width= / height= of the [net] section of a Darknet cfg.
void read_darknet_input_size(const std::filesystem::path& cfg, int& w, int& h) {
  std::ifstream in(cfg);
  if (!in) throw Error(cfg.string() + ": cannot open Darknet cfg");
  std::string line;
  bool in_net = false;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    line.erase(std::remove_if(line.begin(), line.end(), [](unsigned char c) { return std::isspace(c); }),
               line.end());
    if (line.empty() || line[0] == '#' || line[0] == ';') continue;
    if (line[0] == '[') {
      if (in_net) break;
      in_net = line == "[net]" || line == "[network]";
      continue;
    }
    if (!in_net) continue;
    const auto eq = line.find('=');
    if (eq == std::string::npos) continue;
    const std::string key = line.substr(0, eq);
    if (key != "width" && key != "height") continue;
    const std::string text = line.substr(eq + 1);
    int value = 0;
    std::size_t used = 0;
    try {
      value = std::stoi(text, &used);
    } catch (const std::exception&) {
      throw InputError(cfg.string(), line_no, "cannot read '" + key + "' as an integer");
    }
    // Same range as the YAML keys input_width/input_height: a size of 0, a negative one or "320x"
    // was accepted and only failed later, deep in OpenCV's blob code, without naming the cfg line.
    if (used != text.size() || value < 32 || value > 4096) {
      throw InputError(cfg.string(), line_no,
                       "'" + key + "' must be an integer in [32, 4096], got '" + text + "'");
    }
    (key == "width" ? w : h) = value;
  }
}

// exists() without the throwing overload: a configured path that cannot even be looked up (a name
// longer than NAME_MAX, found by fuzz_model_config) must read as "not found", not escape as a
// std::filesystem_error that names neither the YAML file nor the key.
bool file_exists(const std::filesystem::path& p) {
  std::error_code ec;
  return std::filesystem::exists(p, ec);
}

}  // namespace

void DetectorConfig::fit_input_to_image(int long_side, int image_width, int image_height) {
  if (long_side < 32 || image_width <= 0 || image_height <= 0)
    throw Error("detector input: long side " + std::to_string(long_side) + " px for a " +
                std::to_string(image_width) + "x" + std::to_string(image_height) + " image is not usable");
  const auto up32 = [](double v) { return static_cast<int>(std::ceil(v / 32.0)) * 32; };  // v > 0: >= 32
  const double scale = static_cast<double>(long_side) / std::max(image_width, image_height);
  input_width = up32(image_width * scale);
  input_height = up32(image_height * scale);
}

DetectorConfig DetectorConfig::for_model(const std::filesystem::path& model) {
  if (!file_exists(model)) throw Error(model.string() + ": detector model file not found");
  DetectorConfig c;
  c.model = model.string();
  const std::string ext = lower_ext(model);
  std::string stem = model.stem().string();
  std::transform(stem.begin(), stem.end(), stem.begin(), [](unsigned char ch) { return std::tolower(ch); });
  if (ext == ".cfg") {
    c.decoder = "darknet";
    c.input_width = c.input_height = 320;
    read_darknet_input_size(model, c.input_width, c.input_height);
    c.letterbox = false;
    c.swap_rb = true;
    c.scale = 1.0 / 255.0;
    c.weights = std::filesystem::path(model).replace_extension(".weights").string();
    // The person-only "body" variant has a one-class table.
    if (stem.find("body") != std::string::npos) c.class_names = {"person"};
  } else if (ext == ".onnx") {
    if (stem.find("yolox") != std::string::npos) {
      c.decoder = "yolox";
      c.input_width = c.input_height = 416;
      c.letterbox = true;
      c.swap_rb = false;
      c.scale = 1.0;
    } else {
      c.decoder = "yolov7";
      c.input_width = c.input_height = 640;
      c.letterbox = true;
      c.swap_rb = true;
      c.scale = 1.0 / 255.0;
    }
  } else {
    throw Error(model.string() + ": unknown detector model type '" + ext + "' (expected .onnx or .cfg)");
  }
  return c;
}

DetectorConfig DetectorConfig::from_yaml(const ConfigReader& r) {
  DetectorConfig c;
  if (r.has("model")) {
    std::filesystem::path m = r.require<std::string>("model");
    if (m.is_relative() && !r.file().empty()) {
      const auto base = std::filesystem::path(r.file()).parent_path();
      if (file_exists(base / m)) m = base / m;
    }
    // Start from the per-model defaults so a YAML file only lists what differs.
    if (file_exists(m)) c = for_model(m);
    c.model = m.string();
  }
  r.read("weights", c.weights);
  if (!c.weights.empty() && std::filesystem::path(c.weights).is_relative() && !r.file().empty()) {
    const auto w = std::filesystem::path(r.file()).parent_path() / c.weights;
    if (file_exists(w)) c.weights = w.string();
  }
  r.read_choice("decoder", c.decoder, {"auto", "yolov5", "yolov7", "yolox", "darknet"});
  r.read("input_width", c.input_width, 32, 4096);
  r.read("input_height", c.input_height, 32, 4096);
  r.read("letterbox", c.letterbox);
  r.read("swap_rb", c.swap_rb);
  r.read("scale", c.scale, 1e-6, 1e3);
  r.read("conf_threshold", c.conf_threshold, 0.f, 1.f);
  r.read("nms_threshold", c.nms_threshold, 0.f, 1.f);
  r.read("interior_conf_threshold", c.interior_conf_threshold, 0.f, 1.f);
  r.read("border_margin_px", c.border_margin_px, 0.f, 1000.f);
  r.read("class_names", c.class_names);
  r.read("dynamic_classes", c.dynamic_classes);
  r.read("threads", c.threads, 0, 64);
  r.read("fast_sigmoid", c.fast_sigmoid);
  r.read("fast_slice", c.fast_slice);
  for (const auto& name : c.dynamic_classes) {
    if (class_index(c.names(), name) < 0) r.fail("dynamic_classes", "unknown class name '" + name + "'");
  }
  return c;
}

}  // namespace sp::dyn
