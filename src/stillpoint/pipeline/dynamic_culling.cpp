#include "stillpoint/pipeline/dynamic_culling.hpp"

#include <spdlog/spdlog.h>

#include "stillpoint/common/error.hpp"

namespace sp::pipeline {

DynamicConfig DynamicConfig::from_yaml(const ConfigReader& r) {
  DynamicConfig c;
  r.read_choice("mode", c.mode, {"auto", "off", "flow", "detector", "detector+flow", "oracle"});
  r.read("model", c.model);
  r.read("detector_budget_ms", c.detector_budget_ms, 0.0, 1000.0);
  r.read("detector_threads", c.detector_threads, 0, 64);
  r.read("detector_interval", c.detector_interval, 1, 100);
  r.read("detector_input", c.detector_input, 0, 4096);
  if (c.detector_input != 0 && c.detector_input < 32)
    r.fail("detector_input", "must be 0 (the model's own input) or at least 32 px");
  r.read("detector_min_score", c.detector_min_score, 0.0, 1.0);
  r.read("detector_min_score_interior", c.detector_min_score_interior, 0.0, 1.0);
  r.read("detector_nice", c.detector_nice, 0, 19);
  r.read("detector_fast_sigmoid", c.detector_fast_sigmoid);
  r.read("detector_fast_slice", c.detector_fast_slice);
  r.read("refill_share", c.refill_share, 0.0, 1.0);
  r.read("refill_budget", c.refill_budget, 0.0, 10.0);
  r.read("refill_reuse", c.refill_reuse);
  r.read("max_detection_age", c.max_detection_age, 0, 1000);
  r.read("stale_wait_ms", c.stale_wait_ms, 0.0, 10000.0);
  r.read("wait_first_detection", c.wait_first_detection);
  r.read("deterministic_detector_latency", c.deterministic_detector_latency, 0, 100);
  r.read("oracle_moving_only", c.oracle_moving_only);
  if (r.has("detector")) {
    c.detector = dyn::DetectorConfig::from_yaml(r.section("detector"));
    c.detector_configured = true;
  }
  const ConfigReader motion = r.section("motion");
  // The culling mode of the system is `dynamic.mode`; the motion check's own `mode` key (kept for
  // library users of MotionCheckConfig) would be overwritten by it, so here it is refused, not ignored.
  if (motion.has("mode")) {
    motion.fail(
        "mode",
        "not used by the system: set the culling mode with dynamic.mode (auto | off | flow | detector | "
        "detector+flow | oracle)");
  }
  c.motion = dyn::MotionCheckConfig::from_yaml(motion);
  return c;
}

std::string DynamicConfig::resolved_mode() const {
  if (mode != "auto") return mode;
  return model.empty() ? "flow" : "detector+flow";
}

namespace {
dyn::CullMode cull_mode_for(const std::string& mode) {
  if (mode == "flow") return dyn::CullMode::kFlowOnly;
  if (mode == "detector" || mode == "oracle") return dyn::CullMode::kDetectorOnly;
  if (mode == "detector+flow") return dyn::CullMode::kDetectorFlow;
  return dyn::CullMode::kOff;
}
}  // namespace

DynamicCulling::DynamicCulling(const DynamicConfig& config, const geo::CameraIntrinsics& camera,
                               bool deterministic, const std::optional<std::filesystem::path>& boxes_file,
                               const std::filesystem::path& project_root)
    : mode_(config.resolved_mode()),
      budget_ms_(config.detector_budget_ms),
      interval_(config.detector_interval),
      max_detection_age_(config.max_detection_age),
      stale_wait_ms_(config.stale_wait_ms),
      wait_first_detection_(config.wait_first_detection),
      oracle_moving_only_(config.oracle_moving_only) {
  K_ << camera.fx, 0, camera.cx, 0, camera.fy, camera.cy, 0, 0, 1;
  if (mode_ == "off") return;
  if (mode_ == "detector" || mode_ == "detector+flow") {
    if (config.model.empty())
      throw Error("dynamic mode '" + mode_ + "' needs a detector model (--detector-model)");
    model_file_ = config.model;
    if (model_file_.is_relative()) model_file_ = project_root / model_file_;
    dyn::DetectorConfig dc =
        config.detector_configured ? config.detector : dyn::DetectorConfig::for_model(model_file_.string());
    dc.model = model_file_.string();
    if (!config.detector_configured) {
      dc.threads = config.detector_threads;
      dc.fast_sigmoid = config.detector_fast_sigmoid;
      dc.fast_slice = config.detector_fast_slice;
      if (config.detector_input > 0 && dc.decoder == "yolox")
        dc.fit_input_to_image(config.detector_input, camera.width, camera.height);
      if (config.detector_min_score > 0) dc.conf_threshold = static_cast<float>(config.detector_min_score);
      dc.interior_conf_threshold = static_cast<float>(config.detector_min_score_interior);
    }
    detector_config_ = dc;
    detector_ = std::make_unique<dyn::AsyncDetector>(
        dc, deterministic ? dyn::AsyncDetector::Mode::kSync : dyn::AsyncDetector::Mode::kAsync,
        config.detector_nice);
    if (deterministic)
      detector_->set_sync_latency(static_cast<std::size_t>(config.deterministic_detector_latency));
  }
  if (mode_ == "oracle") {
    if (!boxes_file || !std::filesystem::exists(*boxes_file)) {
      throw Error("dynamic mode 'oracle' needs the sequence's boxes.txt (dynsynth sequences have one)");
    }
    oracle_ = dyn::OracleDetections::load(*boxes_file);
  }
  dyn::MotionCheckConfig motion = config.motion;
  motion.mode = cull_mode_for(mode_);
  filter_ = std::make_unique<dyn::DynamicFeatureFilter>(motion);
}

DynamicCulling::~DynamicCulling() {
  if (detector_) detector_->stop();
}

void DynamicCulling::submit(const io::FrameData& data) {
  if (detector_ && data.index % static_cast<std::size_t>(interval_) == 0) {
    detector_->submit(data.index, data.stamp, data.bgr);
  }
}

CullingOutput DynamicCulling::process(const io::FrameData& data, const cv::Mat& gray,
                                      const std::vector<cv::KeyPoint>& keypoints,
                                      const std::optional<geo::SE3>& predicted_T_cur_prev) {
  CullingOutput out;
  if (mode_ == "off") {
    out.drop.assign(keypoints.size(), false);
    return out;
  }
  std::optional<dyn::Detections> detections;
  if (detector_) {
    auto fresh = detector_->wait_for_fresh(
        data.index, std::chrono::milliseconds(static_cast<int>(budget_ms_)),
        static_cast<std::size_t>(max_detection_age_),
        std::chrono::milliseconds(static_cast<int>(stale_wait_ms_)), wait_first_detection_);
    detections = std::move(fresh.detections);
    out.stale_wait_ms = fresh.stale_wait_ms;
  } else if (oracle_) {
    detections = oracle_->at(data.stamp, data.index, oracle_moving_only_);
  }
  if (detections) {
    out.detection_used = true;
    out.detector_ms = detections->inference_ms;
  }
  dyn::DynamicInput in;
  in.frame_index = data.index;
  in.prev_gray = prev_gray_.empty() ? nullptr : &prev_gray_;
  in.gray = &gray;
  in.depth = data.depth.empty() ? nullptr : &data.depth;
  in.keypoints = &keypoints;
  in.detections = detections ? &*detections : nullptr;
  in.K = K_;
  if (predicted_T_cur_prev) {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = predicted_T_cur_prev->rotation();
    T.translation() = predicted_T_cur_prev->translation();
    in.T_cur_prev_predicted = T;
  }
  out.result = filter_->process(in);
  out.drop = out.result.keypoint_dynamic;
  out.suspect = out.result.keypoint_suspect;
  out.reserve = out.result.keypoint_reserve;
  prev_gray_ = gray;
  return out;
}

}  // namespace sp::pipeline
