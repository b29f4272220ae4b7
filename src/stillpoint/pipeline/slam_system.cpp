#include "stillpoint/pipeline/slam_system.hpp"

#include <spdlog/spdlog.h>

namespace sp::pipeline {

namespace {
io::StampedPose to_stamped(double stamp, const geo::SE3& T_wc) {
  return {stamp, T_wc.translation(), T_wc.quaternion().normalized()};
}
track::DepthModel with_camera_range(track::DepthModel d, const io::CameraConfig& cam) {
  d.depth_min = std::max(d.depth_min, cam.depth_min);
  d.depth_max = std::min(d.depth_max, cam.depth_max);
  return d;
}
}  // namespace

SlamSystem::SlamSystem(SystemConfig config, io::CameraConfig camera, const SystemOptions& options)
    : config_(std::move(config)),
      camera_(std::move(camera)),
      deterministic_(options.deterministic),
      frontend_(config_.orb, camera_.intrinsics, with_camera_range(config_.depth, camera_)),
      culling_(config_.dynamic, camera_.intrinsics, options.deterministic, options.boxes_file),
      tracker_(map_, config_.tracker, camera_.intrinsics, with_camera_range(config_.depth, camera_),
               frontend_.pyramid(), camera_.fps),
      mapper_(map_, config_.mapping, camera_.intrinsics, with_camera_range(config_.depth, camera_),
              frontend_.pyramid()) {
  if (options.masks_dir && std::filesystem::is_directory(*options.masks_dir))
    culling_score_.emplace(*options.masks_dir);
  const track::DepthModel depth = with_camera_range(config_.depth, camera_);
  if (config_.loop.detector != "off") {
    std::filesystem::path vocab_file = config_.loop.vocabulary;
    if (vocab_file.is_relative()) vocab_file = options.project_root / vocab_file;
    Stopwatch load;
    auto vocabulary = std::make_shared<const loop::Vocabulary>(loop::Vocabulary::load(vocab_file));
    vocabulary_load_ms_ = load.elapsed_ms();
    vocabulary_words_ = vocabulary->size();
    closer_ = std::make_unique<loop::LoopCloser>(map_, config_.loop, vocabulary, camera_.intrinsics, depth,
                                                 frontend_.pyramid(), deterministic_);
    loop_stage_ = std::make_unique<LoopClosingStage>(*closer_, times_, config_.pipeline.loop_queue);
  }
  LocalMappingStage::Downstream downstream;
  if (loop_stage_) downstream = [this](map::KeyframeId kf) { loop_stage_->submit(kf); };
  mapping_stage_ =
      std::make_unique<LocalMappingStage>(mapper_, times_, downstream, config_.pipeline.mapping_queue);
  if (!deterministic_) {
    if (loop_stage_) loop_stage_->start();
    mapping_stage_->start();
  }
}

SlamSystem::~SlamSystem() { finish(); }

bool SlamSystem::failed() const { return mapping_stage_->failed() || (loop_stage_ && loop_stage_->failed()); }

FrameReport SlamSystem::process(const io::FrameData& data) {
  Stopwatch frame_watch;
  culling_.submit(data);  // detection overlaps feature extraction
  Stopwatch watch;
  ExtractedFeatures features = frontend_.extract(data);
  times_.add("extract", watch.elapsed_ms());
  std::vector<bool> dynamic;
  if (culling_.enabled()) {
    watch.restart();
    CullingOutput culled =
        culling_.process(data, features.gray, features.keypoints, tracker_.predicted_motion());
    times_.add("dynamic", watch.elapsed_ms());
    if (culled.detection_used && culled.detector_ms > 0) times_.add("detector", culled.detector_ms);
    dynamic = std::move(culled.drop);
  }
  if (culling_score_) culling_score_->add(data.rgb_path, features.keypoints, dynamic);
  track::Frame frame = frontend_.assemble(data, std::move(features), dynamic);
  culled_total_ += frame.culled;

  watch.restart();
  const track::MappingStatus mapping{mapping_stage_->idle(), mapping_stage_->queued()};
  const track::TrackOutcome outcome = tracker_.track(frame, mapping);
  times_.add("track", watch.elapsed_ms());
  if (outcome.new_keyframe != map::kNoKeyframe) {
    ++keyframes_created_;
    if (!mapping.idle) mapping_stage_->interrupt_ba();
    mapping_stage_->submit(outcome.new_keyframe);
  }
  times_.add("frame", frame_watch.elapsed_ms());
  ++frames_;
  return {outcome.state, outcome.inliers, frame.features.size(), frame.culled,
          outcome.new_keyframe != map::kNoKeyframe};
}

void SlamSystem::finish() {
  if (finished_) return;
  finished_ = true;
  mapping_stage_->stop();  // drains into the loop stage
  if (loop_stage_) loop_stage_->stop();
  if (closer_) closer_->flush();
}

std::vector<io::StampedPose> SlamSystem::trajectory() {
  map::MapView view = map_.view();
  std::vector<io::StampedPose> out;
  for (const auto& p : tracker_.trajectory().resolve(view)) out.push_back(to_stamped(p.stamp, p.T_wc));
  return out;
}

std::vector<io::StampedPose> SlamSystem::keyframe_trajectory() {
  map::MapView view = map_.view();
  std::vector<io::StampedPose> out;
  for (map::KeyframeId id : view.keyframe_ids_sorted()) {
    const map::Keyframe* kf = view.keyframe(id);
    out.push_back(to_stamped(kf->stamp, kf->T_cw.inverse()));
  }
  return out;
}

nlohmann::json SlamSystem::statistics() {
  nlohmann::json j;
  j["frames"] = frames_;
  j["tracked_frames"] = tracker_.trajectory().size();
  j["lost_frames"] = tracker_.lost_frames();
  j["relocalizations"] = tracker_.relocalizations();
  j["keyframes_created"] = keyframes_created_;
  j["keyframe_policy"] = tracker_.policy().name();
  j["dynamic_mode"] = culling_.mode();
  j["culled_features_total"] = culled_total_;
  if (culling_score_) j["culling_score"] = culling_score_->to_json();
  j["culled_features_per_frame"] =
      frames_ > 0 ? static_cast<double>(culled_total_) / static_cast<double>(frames_) : 0.0;
  {
    map::MapView view = map_.view();
    j["keyframes"] = view.live_keyframes();
    j["map_points"] = view.live_points();
  }
  nlohmann::json stages = nlohmann::json::object();
  for (const auto& [name, s] : times_.summaries()) {
    stages[name] = {{"count", s.count},      {"total_ms", s.total}, {"mean_ms", s.mean},
                    {"median_ms", s.median}, {"p95_ms", s.p95},     {"max_ms", s.max}};
  }
  j["stages_ms"] = stages;
  j["loop_detector"] = closer_ ? config_.loop.detector : std::string("off");
  if (closer_) {
    const auto ls = closer_->stats();
    j["loops_detected"] = ls.loops_detected;
    j["loops_closed"] = ls.loops_closed;
    j["loop_candidates"] = ls.candidates;
    j["loop_queries"] = ls.queries;
    j["loop_detection_ms_total"] = ls.detection_ms_total;
    j["loop_bow_ms_total"] = ls.bow_ms_total;
    j["loop_correction_ms_total"] = ls.correction_ms_total;
    j["global_ba_runs"] = ls.global_ba_runs;
    j["vocabulary_words"] = vocabulary_words_;
    j["vocabulary_load_ms"] = vocabulary_load_ms_;
  }
  j["peak_rss_mib"] = peak_rss_mib();
  j["deterministic"] = deterministic_;
  return j;
}

}  // namespace sp::pipeline
