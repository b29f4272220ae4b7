#pragma once
// Dynamic feature culling: decides which detected objects actually move (sparse LK flow with the
// camera's own motion compensated) and marks the keypoints on them, before pose estimation.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstddef>
#include <deque>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "stillpoint/common/config_reader.hpp"
#include "stillpoint/dynamic/detection.hpp"
#include "stillpoint/dynamic/ego_motion_fit.hpp"

namespace sp::dyn {

enum class CullMode {
  kOff,           // nothing is culled
  kDetectorOnly,  // every box of a dynamic class is culled, no motion check (ablation)
  kFlowOnly,      // no boxes: clusters of moving points are culled (ablation)
  kDetectorFlow,  // boxes culled only when the motion check says they move (the method)
};
// off | detector_only | flow_only | detector_flow (also: detector | flow | detector+flow); throws sp::Error.
CullMode parse_cull_mode(const std::string& s);
const char* to_string(CullMode m);

struct MotionCheckConfig {
  CullMode mode = CullMode::kDetectorFlow;
  // Residual used to call a point moving: "auto" = reprojection when depth and K are given (camera
  // motion from PnP-RANSAC on the flow, predicted pose as its initial guess), else epipolar.
  std::string residual = "auto";  // auto | epipolar | reprojection
  // px, LK window side [5, 61]. 9 tracks as well as 15 on the dev sequences (same ATE) at a third of
  // the cost: the window, not the pyramid, dominates the motion check.
  int lk_window = 9;
  int lk_levels = 3;                 // pyramid levels above the base [0, 6]
  int max_points = 300;              // tracked points per frame (keypoints bucketed on a grid) [20, 5000]
  int grid_cell_px = 24;             // bucketing cell for picking tracked points [4, 200]
  int box_points = 24;               // extra tracked points per candidate box (denser grid inside) [0, 500]
  double fb_max_px = 1.0;            // forward-backward LK error above which a track is dropped [0.1, 10]
  double epsilon_epipolar_px = 1.0;  // epipolar distance above which a point moves [0.1, 20]
  double epsilon_reprojection_px = 2.0;  // reprojection residual above which a point moves [0.1, 50]
  double ransac_threshold_px =
      1.0;                          // F / homography RANSAC inlier threshold (PnP uses the epsilon) [0.1, 20]
  double ransac_confidence = 0.99;  // [0.5, 0.9999]
  // Camera-motion fit of the reprojection residual. "ransac": OpenCV's PnP-RANSAC (inlier count, then a
  // least-squares refinement on all inliers). "msac": hypotheses scored by the truncated squared
  // residual (ego_motion_fit.hpp): a close person walking slowly fits a slightly wrong camera motion
  // within the threshold as well as the background does, which counting inliers cannot tell apart but
  // the residuals' size can. Not the default: it fixed the case it was made for and the tune rooms but
  // not fresh held-back rooms (docs/dynamic.md, step 3).
  std::string ego_fit = "ransac";  // ransac | msac
  // msac: the fitted points without depth (far walls beyond the sensor's range) also score each
  // hypothesis, by their epipolar distance. Off: the epipolar distance cannot see a rotation that
  // compensates a translation error, the case that matters (room207_walking_xyz 0.25 / 0.24 cm with /
  // without), and it costs time.
  bool ego_fit_flat_points = false;
  // msac: residual at which a hypothesis' squared cost is truncated, px; 0 = epsilon_reprojection_px
  // (flat points: epsilon_epipolar_px) [0, 50]. The fit counts as failed (the prediction is kept) when
  // fewer than 30 % of the points with depth lie within it. 0.7 was best on the tune rooms.
  double ego_fit_threshold_px = 0.0;
  // Points without depth (a far wall beyond the sensor's range) under the reprojection residual: a
  // point is also static when it follows the homography that most of the other out-of-box points
  // without depth follow (RANSAC, epsilon_epipolar_px). A motion fitted on a few near points can be a
  // few tenths of a degree off in rotation, which moves far points by 1-2 px across their epipolar
  // lines: "movers" all over a far wall with nobody there. Off: it fixed that room (0.385 -> 0.246 cm) but
  // was not better across eight fresh rooms (walking 9.093 -> 9.163 cm; docs/dynamic.md).
  bool depthless_homography = false;
  int ransac_iterations = 200;  // PnP RANSAC iterations [10, 10000]
  int min_static_points = 15;   // fewer points outside boxes: ego-motion is fitted on all points [8, 1000]
  double moving_ratio_threshold = 0.3;  // share of moving points that makes a box dynamic [0, 1]
  int min_points_to_decide = 5;         // fewer tracked points in a box: undecided [1, 1000]
  std::vector<std::string> always_dynamic_classes = {"person"};  // undecided boxes of these are dynamic
  int dynamic_hold_frames = 10;  // a box that moved stays dynamic this many frames (people pause) [0, 1000]
  // Static until proven: a box of an always-dynamic class stays dynamic until the motion check has
  // found it static in this many consecutive frames (a person is moving unless shown still). 0 = the
  // box is static until seen moving (the paper's literal reading, docs/dynamic.md) [0, 1000].
  int static_proof_frames = 8;
  // A still vote proves a person still only over at least this many points (fewer: undecided, the
  // streak neither grows nor breaks); at most min_points_to_decide = every decided vote counts [1, 1000].
  int min_points_to_prove_still = 5;
  // A person proven still is culled too unless fewer than this many keypoints would remain: people are
  // a last resort, used only when the rest of the image is too poor to track [0, 100000]. 0 = still
  // people are always culled; a value above the keypoint count = always kept (the paper's reading).
  int still_people_fallback_keypoints = 150;
  // ... or unless the keypoints left without them cover less than this share of an 8 x 6 grid over the
  // image: many keypoints in one strip beside a person filling the view pin the pose poorly [0, 1];
  // 0 = the count alone.
  double still_people_fallback_coverage = 0.3;
  // Keypoints culled only because they lie on a person proven still are reported apart
  // (DynamicResult::keypoint_reserve): the tracker keeps them with its keyframes and maps them once the
  // fallback releases the people, so a release finds map points on them (docs/dynamic.md, "A last
  // resort is never mapped"). false = a released person has no map points until the next keyframe.
  bool reserve_still_people = false;
  // A box the camera-motion fit (on the points outside the boxes) calls moving is re-checked: when one
  // camera motion refitted on the fit's inliers and the box's points at the object's depth together
  // keeps both within the residual threshold, the box moved only as much as the fit erred (a person
  // filling most of the view leaves few points to fit on: room209_walking_xyz, docs/dynamic.md) and
  // is seen still. The refit may differ from the first fit only a little: a rotation and a translation
  // together explain any sideways shift of a near layer against a far one, a walker included.
  bool joint_fit_still = true;
  double joint_fit_max_change_m = 0.03;   // m, the refit's translation from the first fit's at most [0, 1]
  double joint_fit_max_change_deg = 0.6;  // deg, its rotation from the first fit's at most [0, 45]
  // A person in use (proven still and kept by the fallback in the frame before) is also checked against
  // the image this many frames back: flow chained through the stored images, the camera motion fitted
  // on the background over that span, then the same joint refit and bounds. A person who starts to
  // walk moves a few millimetres per frame at first, which the one-frame refit's slack absorbs, but
  // the steps add up over the span while the fit's error does not (room209_walking_halfsphere,
  // docs/dynamic.md) [0, 30]; 0 or 1 = off.
  int used_person_baseline_frames = 0;
  // The moving share of a box is counted over the points at the object's depth only, so background
  // seen through a loose box does not outvote the person [true]; false = over all points in the box.
  bool ratio_at_object_depth = true;
  // Keypoints in a dynamic box whose depth differs from the object's by more than the margin
  // (background behind it, furniture in front of it) are kept.
  bool keep_background_in_box = true;
  double background_depth_margin_m = 0.4;  // metres [0.05, 10]
  // A keypoint just outside a dynamic box (within this share of the box's larger side) at the object's
  // depth (within background_depth_margin_m) is the object too: a box carried from a late detection
  // lags a close person and leaves the head or an arm out (docs/dynamic.md). 0 = off [0, 1].
  double object_band_share = 0.0;
  // The same band for the pose guard only: such a keypoint is kept but marked suspect, so it is dropped
  // only on frames whose pose jumps against the prediction (docs/dynamic.md). 0 = off [0, 1].
  double suspect_band_share = 0.0;
  bool cull_unboxed_movers = true;  // moving point clusters outside boxes are culled too
  // A keypoint is not culled for a nearby mover whose depth differs from its own by more than
  // background_depth_margin_m: background seen beside a close person is not the person. Off: measured
  // only together with a 1 px reprojection threshold, which did not generalise (docs/dynamic.md).
  bool unboxed_depth_separated = false;
  // Most of the scene outside the boxes is static: when more than this share of the points the camera
  // motion was fitted on comes out moving, the fit is wrong (RANSAC failed and a poor prediction was
  // kept), and flow decides nothing in this frame: boxes fall back to their class, no unboxed point
  // is culled. 1 = never [0.05, 1].
  double max_moving_share = 0.5;
  // A keypoint whose nearest tracked point (within this radius) is a confirmed mover is culled.
  double unboxed_radius_px = 30.0;  // px [1, 200]
  double cluster_radius_px = 60.0;  // a mover is confirmed with >= cluster_min_points movers this near
  int cluster_min_points = 3;       // [1, 100] (counting itself)
  double box_margin_px = 4.0;       // boxes are grown by this for keypoint tests [0, 100]
  // A box edge this close to the image's edge is moved onto it: a detector's box for a person cut off
  // by the image edge stops short of it and leaves the head or feet out (docs/dynamic.md) [0, 200];
  // 0 = off.
  double border_snap_px = 0.0;
  int max_history_frames = 10;  // flow history for carrying late detections forward [1, 100]
  // A box that moved within dynamic_hold_frames and that the newest detection misses is carried by the
  // flow of its points for up to this many frames after its last detection: one missed detection no
  // longer uncovers a walking person for a whole detector interval (docs/dynamic.md) [0, 100]; 0 = off.
  int coast_frames = 0;
  // Which tracks coast: false = only those the motion check saw move within dynamic_hold_frames;
  // true = any whose box was culled in the frame before (a person still unproven static included:
  // a missed detection of someone at the image border does not uncover them either).
  bool coast_culled = false;

  static MotionCheckConfig from_yaml(const ConfigReader& r);
};

struct DynamicInput {
  std::size_t frame_index = 0;         // increasing frame counter (matches Detections::frame_index)
  const cv::Mat* prev_gray = nullptr;  // CV_8UC1 previous frame; null/empty on the first frame
  const cv::Mat* gray = nullptr;       // CV_8UC1 current frame (required)
  const cv::Mat* depth = nullptr;      // CV_32F metres of the current frame (0 / NaN = none), or null
  const std::vector<cv::KeyPoint>* keypoints = nullptr;  // current frame's keypoints (pixels), or null
  const Detections* detections = nullptr;                // may be null or from an earlier frame
  std::optional<Eigen::Matrix3d> K;  // pinhole intrinsics (needed for the reprojection residual)
  std::optional<Eigen::Isometry3d> T_cur_prev_predicted;  // predicted camera motion prev -> cur
};

struct DynamicResult {
  std::vector<bool> keypoint_dynamic;  // per input keypoint
  // Per input keypoint: kept, but in or near a detected object (a box judged static, background in
  // a dynamic box) or next to a moving flow point. The tracker's pose guard re-solves without these
  // when the pose jumps against the motion model.
  std::vector<bool> keypoint_suspect;
  std::vector<Detection> boxes;          // detections carried to the current frame
  std::vector<bool> box_dynamic;         // per box
  std::vector<cv::Point2f> flow_points;  // tracked points in the current frame
  std::vector<cv::Point2f> flow_prev;    // their positions in the previous frame
  std::vector<float> flow_residual;      // px; negative = no residual (e.g. no depth)
  std::vector<bool> flow_point_moving;
  std::string residual_used;           // "epipolar", "reprojection" or "none"
  int ego_inliers = 0;                 // RANSAC inliers of the camera-motion fit
  bool ego_motion_rejected = false;    // most fitted points moved: flow decided nothing (max_moving_share)
  int culled = 0;                      // keypoints marked dynamic
  bool still_people_released = false;  // people proven still were kept: too few keypoints without them
  // Per input keypoint (empty = none): culled only because it lies on a person proven still; kept if
  // the people were released (reserve_still_people).
  std::vector<bool> keypoint_reserve;
  double ms = 0;  // wall time of process()
};

class DynamicFeatureFilter {
 public:
  explicit DynamicFeatureFilter(const MotionCheckConfig& cfg,
                                const std::vector<std::string>& class_names = coco_class_names());

  // One call per frame, in frame order. Throws sp::Error on inconsistent input (sizes, types).
  DynamicResult process(const DynamicInput& in);

  // Forgets the flow history and the dynamic-box memory (after a reset / relocalisation).
  void reset();

  [[nodiscard]] const MotionCheckConfig& config() const noexcept { return cfg_; }

 private:
  struct FlowStep {               // the tracked pairs of one frame step (prev -> cur), for carrying boxes
    std::size_t frame_index = 0;  // the "cur" frame of the step
    std::vector<cv::Point2f> prev, cur;
  };
  struct BoxTrack {  // one object followed over frames by box overlap
    cv::Rect2f box;
    int class_id = 0;
    std::size_t last_seen_frame = 0;
    std::size_t last_detected_frame = 0;            // last frame a detection (not coasting) placed it
    std::optional<std::size_t> last_dynamic_frame;  // last frame the motion check saw it move
    std::optional<std::size_t> last_culled_frame;   // last frame its box was culled (for any reason)
    int static_streak = 0;                          // consecutive frames the motion check saw it still
    std::optional<std::size_t> last_used_frame;     // last frame it was proven still and kept (in use)
  };
  struct StoredFrame {  // one frame's LK pyramid and camera motion, for used_person_baseline_frames
    std::size_t frame_index = 0;
    std::vector<cv::Mat> pyramid;
    std::optional<CameraMotion> motion;  // to the frame before, when the reprojection fit ran
  };

  std::vector<Detection> carry_boxes(const Detections& d, std::size_t to_frame) const;
  // Boxes of recently moving tracks that no carried detection overlaps, moved by this frame's flow.
  std::vector<Detection> coast_boxes(const std::vector<Detection>& detected, std::size_t frame) const;
  // The camera motion the reprojection residuals were computed under, and every tracked point
  // back-projected into the current camera (has_z: it had depth), for the joint refit.
  struct EgoFit {
    CameraMotion motion;
    std::vector<cv::Point3f> X;
    std::vector<bool> has_z;
  };
  // The MSAC settings of every camera-motion fit, and whether a fit on `points` points with depth has
  // enough inliers to be trusted (else the prediction is kept).
  MsacOptions msac_options() const;
  static bool enough_inliers(int inliers, std::size_t points);
  // Fill res.flow_residual and eps (per-point threshold) from the points `fit` (static candidates).
  // Reprojection: camera motion by PnP-RANSAC on depth; false when it cannot be estimated. `ego` (may
  // be null) receives the motion and the back-projected points.
  bool reprojection_residuals(const DynamicInput& in, const std::vector<int>& fit, DynamicResult& res,
                              std::vector<float>& eps, EgoFit* ego = nullptr) const;
  // joint_fit_still: whether one camera motion, refitted from ego's on the tracked points `background`
  // (the camera fit's inliers) and `object` (a box's points) together, keeps both groups within the
  // reprojection threshold (moving share below moving_ratio_threshold in each). Points without depth
  // are left out.
  bool explained_by_camera(const Eigen::Matrix3d& K, const CameraMotion& motion, const EgoFit& ego,
                           const std::vector<cv::Point2f>& prev_px,
                           const std::vector<std::size_t>& background,
                           const std::vector<std::size_t>& object) const;
  // used_person_baseline_frames: whether the tracked points `object` moved against `background` (the
  // camera fit's inliers) since the oldest stored frame, judged as one frame step is (camera fit on the
  // background, then the joint refit). nullopt: too few stored frames or points to judge.
  std::optional<bool> moved_over_baseline(const DynamicInput& in, const DynamicResult& res, const EgoFit& ego,
                                          const std::vector<std::size_t>& background,
                                          const std::vector<std::size_t>& object) const;
  // Epipolar distance to an F fitted by RANSAC, or the homography transfer error when a homography
  // explains the motion as well (static or rotating camera, far scene: F is degenerate there).
  void epipolar_residuals(const std::vector<int>& fit, DynamicResult& res, std::vector<float>& eps) const;
  // depthless_homography: lowers the residual of each point without depth to its transfer error under
  // the homography most out-of-box points without depth follow, when there is one.
  void depthless_homography_residuals(const std::vector<int>& fit, const std::vector<bool>& has_z,
                                      DynamicResult& res) const;

  MotionCheckConfig cfg_;
  std::vector<bool> always_dynamic_;  // class id -> always dynamic
  std::deque<FlowStep> history_;
  std::vector<BoxTrack> tracks_;
  cv::Mat cached_gray_;  // last current image and its LK pyramid, reused as "previous"
  std::vector<cv::Mat> cached_pyr_;
  std::deque<StoredFrame> stored_;  // the newest used_person_baseline_frames + 1 frames, consecutive
};

}  // namespace sp::dyn
