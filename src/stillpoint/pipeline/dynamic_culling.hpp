#pragma once
// The dynamic-culling step of the front end: hands each frame to the detector thread, takes the
// newest detection within a time budget, and asks the motion check which features move.
#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "stillpoint/common/config_reader.hpp"
#include "stillpoint/dynamic/async_detector.hpp"
#include "stillpoint/dynamic/dynamic_filter.hpp"
#include "stillpoint/dynamic/oracle_detections.hpp"
#include "stillpoint/geometry/camera.hpp"
#include "stillpoint/geometry/lie.hpp"
#include "stillpoint/io/frame.hpp"

namespace sp::pipeline {

struct DynamicConfig {
  // off | flow | detector | detector+flow | oracle | auto (= detector+flow with a model, else flow)
  std::string mode = "auto";
  std::string model;  // detector model (.onnx or Darknet .cfg); empty = none; relative: from the project root
  double detector_budget_ms = 0.0;  // ms tracking may wait for the current frame's detection
  int detector_threads = 1;         // OpenCV threads for inference (the other core tracks and maps)
  int detector_interval = 3;        // detect every N-th frame; boxes are carried by flow in between
  // Long side of the YOLOX input, px (short side from the camera's aspect; 0 = the model's 416x416).
  // 320 halves the detector's cost with the same culling recall on the tune rooms (docs/dynamic.md):
  // people indoors are large, so the lost resolution costs nothing and the detector keeps up.
  int detector_input = 320;
  // Detections scoring below this are dropped (0 = the model's own conf_threshold, 0.35 for every
  // shipped model). 0.25 keeps people half out of the view (their scores hover around 0.3): on the tune
  // rooms, threaded, culling recall +1 to +9 points and walking ATE 6 % lower (docs/dynamic.md). Applies
  // to the model's defaults only; a `detector` section sets its own conf_threshold.
  double detector_min_score = 0.25;
  // Boxes that do not reach the image border need at least this score (0 = detector_min_score alone).
  // Meant for people cut by the image edge, but people in full view score as low: on the tune rooms it
  // cost recall and ATE, so it is off (docs/dynamic.md). Model defaults only, like detector_min_score.
  double detector_min_score_interior = 0.0;
  // Scheduling niceness of the detector thread (0 = as tracking). 2 keeps tracking within +5 ms of
  // culling-off on 2 cores; 5 and more starve the detector and stale boxes cost accuracy (docs/dynamic.md).
  int detector_nice = 2;
  // The detector's Sigmoid layers vectorised (dyn::fast_sigmoid; the same boxes, YOLOX-nano forward
  // 32 vs 40 ms, docs/dynamic.md); false = OpenCV's own layer. A `detector` section sets its own.
  bool detector_fast_sigmoid = true;
  // The detector's Slice layers as strided copies (dyn::ScopedFastSlice; the same boxes, YOLOX-nano's
  // input slicing ~5 ms -> < 1 ms, docs/dynamic.md); false = OpenCV's own layer.
  bool detector_fast_slice = true;
  // Where culling removed more than this share of a frame's features, detection runs again away from
  // the moving objects so the static part gets the keypoint budget (a person filling the view of a
  // bare room left too few features to start the map). 0: never.
  double refill_share = 0.3;
  // Refill at most this many times the removed feature count (the frame regains about its ORB budget
  // and tracking does not pay for surplus features); 0: a whole n_features budget.
  double refill_budget = 1.0;
  // Refill selects among the corners the first detection found (no second FAST pass and blur).
  bool refill_reuse = true;
  // A detection older than this many frames is too stale to carry (a person entering the view is in
  // no box yet): tracking then waits up to stale_wait_ms for a newer one. Only a detector falling
  // behind (a loaded CPU) makes detections this old. 0: never wait.
  int max_detection_age = 4;
  double stale_wait_ms = 200.0;
  // The first frames wait (up to stale_wait_ms) for the detector's first boxes instead of starting
  // the map with no culling: threaded, the first keyframe was made before any detection existed, its
  // points on the people in view (deterministic runs see frame 0's boxes at once either way). Off:
  // on fresh rooms 245-248 it made the walking sum worse (3.71 -> 3.78 cm, docs/dynamic.md).
  bool wait_first_detection = false;
  // --deterministic only: a detection is seen this many frames after its frame (0: at once, as a
  // synchronous detector). Reproduces, repeatably, the late boxes of a threaded run on a busy CPU
  // (there: 1 to max_detection_age + 2 frames), for tests and for diagnosing failures seen threaded.
  int deterministic_detector_latency = 0;
  // mode oracle: cull the ground-truth boxes of moving people only (true: what the oracle means), or of
  // every person, still ones too (false: for measuring what still people's features are worth).
  bool oracle_moving_only = true;
  dyn::DetectorConfig detector;  // used as given when the file sets `detector`, else from the model
  bool detector_configured = false;
  dyn::MotionCheckConfig motion;
  static DynamicConfig from_yaml(const ConfigReader& r);
  // The mode actually used: resolves auto.
  [[nodiscard]] std::string resolved_mode() const;
};

struct CullingOutput {
  std::vector<bool> drop;     // per keypoint
  std::vector<bool> suspect;  // per keypoint: kept but near a detected object (pose guard)
  std::vector<bool> reserve;  // per keypoint (empty = none): dropped only as a person proven still
  dyn::DynamicResult result;
  double detector_ms = 0;  // inference time of the detection used (0 when none)
  bool detection_used = false;
  double stale_wait_ms = 0;  // time spent waiting because the newest detection was too old
};

class DynamicCulling {
 public:
  // `boxes_file` is the sequence's boxes.txt (needed by oracle mode). A relative `config.model` resolves
  // against `project_root` (as loop_closing.vocabulary does); absolute paths are used as given.
  DynamicCulling(const DynamicConfig& config, const geo::CameraIntrinsics& camera, bool deterministic,
                 const std::optional<std::filesystem::path>& boxes_file,
                 const std::filesystem::path& project_root = ".");
  ~DynamicCulling();
  DynamicCulling(const DynamicCulling&) = delete;
  DynamicCulling& operator=(const DynamicCulling&) = delete;

  [[nodiscard]] bool enabled() const { return mode_ != "off"; }
  [[nodiscard]] const std::string& mode() const { return mode_; }
  // The detector model file in use (resolved path); empty when no detector runs.
  [[nodiscard]] const std::filesystem::path& model_file() const { return model_file_; }
  // The detector's settings as used (model defaults with the dynamic.detector_* keys applied).
  [[nodiscard]] const dyn::DetectorConfig& detector_config() const { return detector_config_; }
  // Starts detection of a frame early (right after decoding) so it overlaps feature extraction.
  void submit(const io::FrameData& data);
  CullingOutput process(const io::FrameData& data, const cv::Mat& gray,
                        const std::vector<cv::KeyPoint>& keypoints,
                        const std::optional<geo::SE3>& predicted_T_cur_prev);

 private:
  std::string mode_;
  double budget_ms_;
  int interval_;
  int max_detection_age_;
  double stale_wait_ms_;
  bool wait_first_detection_;
  bool oracle_moving_only_;
  Eigen::Matrix3d K_;
  std::filesystem::path model_file_;
  dyn::DetectorConfig detector_config_;
  std::unique_ptr<dyn::AsyncDetector> detector_;
  std::optional<dyn::OracleDetections> oracle_;
  std::unique_ptr<dyn::DynamicFeatureFilter> filter_;
  cv::Mat prev_gray_;
};

}  // namespace sp::pipeline
