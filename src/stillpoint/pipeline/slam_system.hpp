#pragma once
// The System wires the stages: front end (features, dynamic culling) and tracking on the caller's
// thread, local mapping and loop closing on their own threads, joined by bounded queues. With
// `deterministic` every stage runs in lock-step on the caller's thread.
#include <deque>
#include <memory>
#include <nlohmann/json.hpp>
#include <vector>

#include "stillpoint/common/timing.hpp"
#include "stillpoint/io/camera_config.hpp"
#include "stillpoint/io/frame.hpp"
#include "stillpoint/io/trajectory_io.hpp"
#include "stillpoint/loop/keyframe_database.hpp"
#include "stillpoint/map/map.hpp"
#include "stillpoint/map/map_file.hpp"
#include "stillpoint/pipeline/culling_score.hpp"
#include "stillpoint/pipeline/dynamic_culling.hpp"
#include "stillpoint/pipeline/frontend.hpp"
#include "stillpoint/pipeline/local_mapping_stage.hpp"
#include "stillpoint/pipeline/loop_closing_stage.hpp"
#include "stillpoint/pipeline/relocalization_index.hpp"
#include "stillpoint/pipeline/run_artifacts.hpp"
#include "stillpoint/pipeline/system_config.hpp"

namespace sp::pipeline {

struct FrameReport {
  track::TrackingState state = track::TrackingState::NotInitialized;
  int inliers = 0;
  std::size_t features = 0;
  std::size_t culled = 0;
  bool keyframe = false;
  map::KeyframeId keyframe_id = map::kNoKeyframe;  // the keyframe this frame became, if any
  // The frame's camera pose as tracked (T_world_camera), when the tracker gave one (state Ok). Later
  // map corrections move it; trajectory() resolves every pose against the corrected map.
  std::optional<geo::SE3> T_wc;
  std::vector<cv::Point2f> culled_points;  // image positions of the features dropped as dynamic
};

// Whether this build has ParC_NetVLAD (libtorch): without it the 'netvlad' loop detector is refused.
[[nodiscard]] bool has_place_recognition();
// The message for a run that asks for 'netvlad' in a build without it.
[[nodiscard]] std::string netvlad_unavailable_message(const std::string& detector = "netvlad");

struct SystemOptions {
  bool deterministic = false;
  std::optional<std::filesystem::path> boxes_file;  // oracle detections (dynsynth boxes.txt)
  std::optional<std::filesystem::path> masks_dir;   // score culling against ground-truth masks
  std::filesystem::path project_root = ".";         // relative resource paths (vocabulary) resolve here
  ArtifactOptions artifacts;  // PLY clouds and culled-feature thumbnails (off by default)
};

class SlamSystem {
 public:
  SlamSystem(SystemConfig config, io::CameraConfig camera, const SystemOptions& options);
  ~SlamSystem();
  SlamSystem(const SlamSystem&) = delete;
  SlamSystem& operator=(const SlamSystem&) = delete;

  // Loads a saved map (map_file.hpp) before the first frame: the tracker relocalises in it and extends
  // it, relocalisation candidates come from a BoW database over its keyframes (or, without a
  // vocabulary, a whole-image score), and the loop closer knows its keyframes. Throws sp::InputError
  // for a damaged file or one built for another camera or ORB pyramid.
  void load_map(const std::filesystem::path& file);
  // Saves the live map (call after finish()). Throws sp::Error when the file cannot be written.
  map::MapSaveResult save_map(const std::filesystem::path& file);

  FrameReport process(const io::FrameData& frame);
  // Waits for the background stages to finish their queues and stops them.
  void finish();

  [[nodiscard]] std::vector<io::StampedPose> trajectory();
  [[nodiscard]] std::vector<io::StampedPose> keyframe_trajectory();
  // Per frame of trajectory(), in the same order: the map its pose is in (0 = the first map, or a map
  // merged into it; another id = a map started after a loss and never merged, its own frame).
  [[nodiscard]] std::vector<std::pair<double, std::uint32_t>> trajectory_maps();
  // Positions of the live map points, at most `max` (evenly subsampled), for a live view.
  [[nodiscard]] std::vector<Eigen::Vector3f> map_point_positions(std::size_t max);
  [[nodiscard]] nlohmann::json statistics();
  // Loops closed so far (empty without loop closing).
  [[nodiscard]] std::vector<loop::LoopClosure> loop_closures() const;
  // Writes map_points.ply, dense_cloud.ply and culled/index.json (when enabled); figures for stats.json.
  nlohmann::json write_artifacts();
  [[nodiscard]] StageTimes& times() { return times_; }
  [[nodiscard]] bool failed() const;
  // The failed stage and its error (empty while none failed).
  [[nodiscard]] std::string failure() const;

 private:
  // The BoW relocalisation database over every keyframe (when a vocabulary is available): filled as
  // keyframes leave local mapping (loop closing computes their vectors when it runs), culled keyframes
  // erased from it and from the loop detectors.
  void attach_relocalization_index();
  // Erases culled keyframes from the relocalisation database and the loop detectors.
  void erase_culled_keyframes();
  // Loads the ParC_NetVLAD model and hands the loop closer its keyframe describer (netvlad detector).
  void attach_place_model(const std::filesystem::path& project_root);
  SystemConfig config_;
  io::CameraConfig camera_;
  bool deterministic_;
  StageTimes times_;
  map::Map map_;
  FrontEnd frontend_;
  DynamicCulling culling_;
  std::optional<CullingScore> culling_score_;
  track::Tracker tracker_;
  mapping::LocalMapper mapper_;
  std::unique_ptr<loop::LoopCloser> closer_;
  std::unique_ptr<LoopClosingStage> loop_stage_;
  std::unique_ptr<LocalMappingStage> mapping_stage_;
  std::size_t frames_ = 0;
  std::size_t culled_total_ = 0;
  std::size_t refilled_total_ = 0;       // features added by FrontEnd::refill
  std::size_t ego_motion_rejected_ = 0;  // frames whose camera-motion fit the motion check rejected
  std::size_t keyframes_created_ = 0;
  // Deterministic mapping latency: keyframes held back, with the frame index from which they go on.
  std::deque<std::pair<std::size_t, map::KeyframeId>> delayed_keyframes_;
  bool finished_ = false;
  double vocabulary_load_ms_ = 0;
  double place_model_load_ms_ = 0;
  std::size_t vocabulary_words_ = 0;
  std::filesystem::path project_root_;
  std::shared_ptr<const loop::Vocabulary> vocabulary_;
  std::filesystem::path vocabulary_file_;
  std::unique_ptr<RelocalizationIndex> reloc_index_;  // every keyframe, for relocalisation
  nlohmann::json map_file_stats_ = nlohmann::json::object();
  RunArtifacts artifacts_;
};

}  // namespace sp::pipeline
