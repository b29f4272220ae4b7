#include "stillpoint/pipeline/slam_system.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "stillpoint/common/error.hpp"
#ifdef SP_HAVE_PLACE
#include "stillpoint/place/descriptor.hpp"
#endif

#include <algorithm>
#include <cmath>
#include <map>
#include <opencv2/imgproc.hpp>

#include "stillpoint/common/error.hpp"

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

bool has_place_recognition() {
#ifdef SP_HAVE_PLACE
  return true;
#else
  return false;
#endif
}

std::string netvlad_unavailable_message(const std::string& detector) {
  return "loop detector '" + detector +
         "' (ParC_NetVLAD) is not available: this StillPoint was built without "
         "libtorch (-DSTILLPOINT_WITH_TORCH=OFF); use loop_closing.detector bow-sequence or bow-keyframe, "
         "or rebuild with libtorch (Debian libtorch-dev)";
}

SlamSystem::SlamSystem(SystemConfig config, io::CameraConfig camera, const SystemOptions& options)
    : config_(std::move(config)),
      camera_(std::move(camera)),
      deterministic_(options.deterministic),
      frontend_(config_.orb, camera_.intrinsics, with_camera_range(config_.depth, camera_)),
      culling_(config_.dynamic, camera_.intrinsics, options.deterministic, options.boxes_file,
               options.project_root),
      tracker_(map_, config_.tracker, camera_.intrinsics, with_camera_range(config_.depth, camera_),
               frontend_.pyramid(), camera_.fps),
      mapper_(map_, config_.mapping, camera_.intrinsics, with_camera_range(config_.depth, camera_),
              frontend_.pyramid()),
      artifacts_(options.artifacts, camera_.intrinsics) {
  project_root_ = options.project_root;
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
    vocabulary_ = vocabulary;
    vocabulary_file_ = vocab_file;
    closer_ = std::make_unique<loop::LoopCloser>(map_, config_.loop, vocabulary, camera_.intrinsics, depth,
                                                 frontend_.pyramid(), deterministic_);
    if (closer_->needs_global_descriptors()) attach_place_model(options.project_root);
    loop_stage_ = std::make_unique<LoopClosingStage>(*closer_, times_, config_.pipeline.loop_queue);
  }
  // Relocalisation wants a vocabulary even when loop detection is off.
  if (!vocabulary_) {
    std::filesystem::path vocab_file = config_.loop.vocabulary;
    if (vocab_file.is_relative()) vocab_file = options.project_root / vocab_file;
    try {
      Stopwatch load;
      vocabulary_ = std::make_shared<const loop::Vocabulary>(loop::Vocabulary::load(vocab_file));
      vocabulary_load_ms_ = load.elapsed_ms();
      vocabulary_words_ = vocabulary_->size();
      vocabulary_file_ = vocab_file;
    } catch (const Error& e) {
      spdlog::warn("no vocabulary for relocalisation ({}): candidates are the recent keyframes", e.what());
    }
  }
  if (vocabulary_) attach_relocalization_index();
  LocalMappingStage::Downstream downstream = [this](map::KeyframeId kf) {
    if (reloc_index_ && !closer_) {
      // No loop closing to compute the vector: local mapping's thread does (ORB-SLAM computes it there).
      cv::Mat descriptors;
      {
        map::MapView view = map_.view();
        const map::Keyframe* k = view.keyframe(kf);
        if (k != nullptr && !k->bad) descriptors = k->features.descriptors.clone();
      }
      if (!descriptors.empty()) reloc_index_->add(kf, reloc_index_->describe(descriptors));
    }
    erase_culled_keyframes();
    if (loop_stage_) loop_stage_->submit(kf);
  };
  mapping_stage_ =
      std::make_unique<LocalMappingStage>(mapper_, times_, downstream, config_.pipeline.mapping_queue);
  if (!deterministic_) {
    if (loop_stage_) loop_stage_->start(config_.pipeline.loop_nice);
    mapping_stage_->start(config_.pipeline.mapping_nice);
  }
}

SlamSystem::~SlamSystem() { finish(); }

void SlamSystem::attach_relocalization_index() {
  reloc_index_ = std::make_unique<RelocalizationIndex>(vocabulary_);
  if (closer_) {
    closer_->set_keyframe_filed([this](map::KeyframeId kf, const loop::BowVector& bow) {
      reloc_index_->add(kf, bow);
      // Culled while its vector was computed: the scan after local mapping may have missed it.
      erase_culled_keyframes();
    });
  }
  tracker_.set_relocalization_candidates(
      [index = reloc_index_.get(), n = config_.tracker.relocalization_candidates](const map::MapReader&,
                                                                                  const track::Frame& frame) {
        return index->candidates(frame.features.descriptors, n);
      });
  // Map merging asks the same database for other maps' keyframes only: the current map's own keyframes
  // would otherwise crowd them out of the query's 80 % rule.
  tracker_.set_other_map_candidates(
      [index = reloc_index_.get(), n = config_.tracker.relocalization_candidates](
          const map::MapReader& view, const track::Frame& frame, map::MapId current) {
        return index->candidates(frame.features.descriptors, n, [&view, current](map::KeyframeId id) {
          const map::Keyframe* kf = view.keyframe(id);
          return kf == nullptr || kf->bad || kf->map_id == current;
        });
      });
}

void SlamSystem::erase_culled_keyframes() {
  if (!reloc_index_) return;
  std::vector<map::KeyframeId> culled;
  {
    map::MapView view = map_.view();
    culled = reloc_index_->erase_culled(view);
  }
  if (closer_ && !culled.empty()) closer_->erase_keyframes(culled);
}

void SlamSystem::attach_place_model([[maybe_unused]] const std::filesystem::path& project_root) {
#ifdef SP_HAVE_PLACE
  std::filesystem::path model = config_.loop.place_model;
  if (model.is_relative()) model = project_root / model;
  Stopwatch load;
  // One libtorch thread: the loop thread shares 2 cores with tracking, mapping and the detector.
  auto extractor =
      std::make_shared<place::PlaceDescriptorExtractor>(place::PlaceDescriptorExtractor::load(model, 1));
  place_model_load_ms_ = load.elapsed_ms();
  // Only the loop-closing thread calls it (the extractor is not thread-safe).
  closer_->set_global_describer([extractor](const cv::Mat& bgr) { return extractor->describe(bgr); });
#else
  throw Error(netvlad_unavailable_message(config_.loop.detector));
#endif
}

namespace {
// Whole-image similarity for relocalisation without a vocabulary: 32x24 grey thumbnails, zero mean,
// unit norm, so the dot product is the normalised cross-correlation.
cv::Mat tiny_image(const cv::Mat& thumbnail) {
  if (thumbnail.empty()) return {};
  cv::Mat grey, small, f;
  if (thumbnail.channels() == 3) {
    cv::cvtColor(thumbnail, grey, cv::COLOR_BGR2GRAY);
  } else {
    grey = thumbnail;
  }
  cv::resize(grey, small, cv::Size(32, 24), 0, 0, cv::INTER_AREA);
  small.convertTo(f, CV_32F);
  f -= cv::mean(f)[0];
  const double n = cv::norm(f);
  if (n > 0) f /= n;
  return f;
}
}  // namespace

void SlamSystem::load_map(const std::filesystem::path& file) {
  if (frames_ > 0) throw Error("load_map: the system has already processed frames");
  Stopwatch watch;
  const map::MapFileInfo info = map::load_map(file, map_);
  const double load_ms = watch.elapsed_ms();
  // The map's keypoints, octaves and depths only mean something for the camera and pyramid it was
  // built with.
  const geo::CameraIntrinsics& c = camera_.intrinsics;
  const geo::CameraIntrinsics& m = info.camera;
  const auto differs = [](double a, double b) { return std::abs(a - b) > 1e-6 * std::max(1.0, std::abs(b)); };
  if (c.width != m.width || c.height != m.height || differs(c.fx, m.fx) || differs(c.fy, m.fy) ||
      differs(c.cx, m.cx) || differs(c.cy, m.cy)) {
    throw InputError(
        file.string(), 0,
        fmt::format("the map was built for a {}x{} camera (fx {} fy {} cx {} cy {}), this run's camera "
                    "is {}x{} (fx {} fy {} cx {} cy {})",
                    m.width, m.height, m.fx, m.fy, m.cx, m.cy, c.width, c.height, c.fx, c.fy, c.cx, c.cy));
  }
  const map::ScalePyramid pyramid = frontend_.pyramid();
  if (pyramid.levels != info.pyramid_levels || differs(pyramid.scale_factor, info.pyramid_scale_factor)) {
    throw InputError(
        file.string(), 0,
        fmt::format("the map was built with an ORB pyramid of {} levels x {}, the configuration has {} x {}",
                    info.pyramid_levels, info.pyramid_scale_factor, pyramid.levels, pyramid.scale_factor));
  }
  if (vocabulary_ && !info.vocabulary_name.empty()) {
    const std::uint64_t checksum = map::vocabulary_fingerprint(vocabulary_file_);
    if (checksum != info.vocabulary_checksum || vocabulary_->size() != info.vocabulary_words) {
      // BoW vectors are not stored in the file, so this is not fatal: they are recomputed below.
      spdlog::warn(
          "{}: the map was built with vocabulary {} ({} words, checksum {:016x}); "
          "this run uses {} ({} words, checksum {:016x}); BoW vectors are recomputed with it",
          file.string(), info.vocabulary_name, info.vocabulary_words, info.vocabulary_checksum,
          vocabulary_file_.filename().string(), vocabulary_->size(), checksum);
    }
  }
  std::vector<loop::KeyframeInfo> keyframes;
  std::size_t points = 0;
  {
    map::MapView view = map_.view();
    for (map::KeyframeId id : view.keyframe_ids_sorted()) {
      const map::Keyframe* kf = view.keyframe(id);
      loop::KeyframeInfo k;
      k.id = id;
      k.R_cw = kf->T_cw.rotation();
      keyframes.push_back(std::move(k));
    }
    points = view.live_points();
  }
  tracker_.start_in_existing_map();
  Stopwatch bow_watch;
  std::string candidates = "thumbnail";
  if (reloc_index_) {
    for (loop::KeyframeInfo& k : keyframes) {
      cv::Mat descriptors;
      {
        map::MapView view = map_.view();
        descriptors = view.keyframe(k.id)->features.descriptors;
      }
      k.bow = reloc_index_->describe(descriptors);
      reloc_index_->add(k.id, k.bow);
    }
    if (closer_) closer_->add_existing_keyframes(keyframes);
    candidates = "bow";
  } else {
    tracker_.set_relocalization_candidates([n = config_.tracker.relocalization_candidates](
                                               const map::MapReader& view, const track::Frame& frame) {
      const cv::Mat query = tiny_image(frame.thumbnail);
      std::vector<std::pair<double, map::KeyframeId>> scored;
      for (map::KeyframeId id : view.keyframe_ids_sorted()) {
        const cv::Mat t = tiny_image(view.keyframe(id)->thumbnail);
        const double s = query.empty() || t.empty() ? -1.0 : query.dot(t);
        scored.emplace_back(-s, id);
      }
      std::sort(scored.begin(), scored.end());
      std::vector<map::KeyframeId> out;
      for (std::size_t i = 0; i < scored.size() && i < n; ++i) out.push_back(scored[i].second);
      return out;
    });
  }
  map_file_stats_["map_loaded"] = {
      {"file", file.string()}, {"keyframes", keyframes.size()},    {"points", points},
      {"load_ms", load_ms},    {"bow_ms", bow_watch.elapsed_ms()}, {"relocalization_candidates", candidates}};
  spdlog::info("loaded map {}: {} keyframes, {} points in {:.0f} ms; relocalising in it", file.string(),
               keyframes.size(), points, load_ms);
}

map::MapSaveResult SlamSystem::save_map(const std::filesystem::path& file) {
  if (tracker_.open_maps().size() > 1) {
    // Each keyframe keeps its map id in the file, so a loaded copy keeps the maps apart (all open).
    spdlog::info("saving {} maps that were never merged; each keeps its own frame and map id",
                 tracker_.open_maps().size());
  }
  map::MapFileInfo info;
  info.camera = camera_.intrinsics;
  const map::ScalePyramid pyramid = frontend_.pyramid();
  info.pyramid_levels = pyramid.levels;
  info.pyramid_scale_factor = pyramid.scale_factor;
  if (vocabulary_) {
    info.vocabulary_name = vocabulary_file_.filename().string();
    info.vocabulary_words = vocabulary_->size();
    info.vocabulary_checksum = map::vocabulary_fingerprint(vocabulary_file_);
  }
  Stopwatch watch;
  const map::MapSaveResult r = map::save_map(map_, file, info);
  const double ms = watch.elapsed_ms();
  map_file_stats_["map_saved"] = {{"file", file.string()},
                                  {"keyframes", r.keyframes},
                                  {"points", r.points},
                                  {"bytes", r.bytes},
                                  {"save_ms", ms}};
  spdlog::info("saved map {}: {} keyframes, {} points, {:.1f} MB in {:.0f} ms", file.string(), r.keyframes,
               r.points, static_cast<double>(r.bytes) / 1e6, ms);
  return r;
}

bool SlamSystem::failed() const { return mapping_stage_->failed() || (loop_stage_ && loop_stage_->failed()); }

std::string SlamSystem::failure() const {
  if (mapping_stage_->failed()) return mapping_stage_->failure();
  if (loop_stage_ && loop_stage_->failed()) return loop_stage_->failure();
  return {};
}

FrameReport SlamSystem::process(const io::FrameData& data) {
  Stopwatch frame_watch;
  culling_.submit(data);  // detection overlaps feature extraction
  Stopwatch watch;
  ExtractedFeatures features = frontend_.extract(data);
  times_.add("extract", watch.elapsed_ms());
  std::vector<bool> dynamic, suspect, reserve;
  CullingOutput culled;
  if (culling_.enabled()) {
    watch.restart();
    culled = culling_.process(data, features.gray, features.keypoints, tracker_.predicted_motion());
    times_.add("dynamic", watch.elapsed_ms());
    if (culled.detection_used && culled.detector_ms > 0) times_.add("detector", culled.detector_ms);
    if (culled.stale_wait_ms > 0) times_.add("stale_wait", culled.stale_wait_ms);
    if (culled.result.ego_motion_rejected) ++ego_motion_rejected_;
    dynamic = std::move(culled.drop);
    suspect = std::move(culled.suspect);
    reserve = std::move(culled.reserve);
  }
  std::vector<cv::Point2f> culled_points;
  for (std::size_t i = 0; i < dynamic.size() && i < features.keypoints.size(); ++i)
    if (dynamic[i]) culled_points.push_back(features.keypoints[i].pt);
  artifacts_.on_frame(data, features.keypoints, dynamic, culled.result.boxes, culled.result.box_dynamic);
  if (culling_score_) culling_score_->add(data.rgb_path, features.keypoints, dynamic);
  const double refill_share = config_.dynamic.refill_share;
  if (refill_share > 0 && !features.keypoints.empty() &&
      static_cast<double>(culled_points.size()) >
          refill_share * static_cast<double>(features.keypoints.size())) {
    watch.restart();
    std::vector<cv::Rect2f> boxes;
    for (std::size_t b = 0; b < culled.result.boxes.size(); ++b)
      if (b < culled.result.box_dynamic.size() && culled.result.box_dynamic[b])
        boxes.push_back(culled.result.boxes[b].box);
    feat::OrbExtractor::AgainOptions again;
    again.max_keypoints = static_cast<int>(
        std::lround(config_.dynamic.refill_budget * static_cast<double>(culled_points.size())));
    again.reuse_detections = config_.dynamic.refill_reuse;
    refilled_total_ += frontend_.refill(features, dynamic, suspect, boxes, again);
    times_.add("refill", watch.elapsed_ms());
  }
  track::Frame frame = frontend_.assemble(data, std::move(features), dynamic, suspect, reserve);
  culled_total_ += frame.culled;

  watch.restart();
  const auto latency = static_cast<std::size_t>(config_.pipeline.deterministic_mapping_latency);
  while (!delayed_keyframes_.empty() && delayed_keyframes_.front().first <= data.index) {
    mapping_stage_->submit(delayed_keyframes_.front().second);
    delayed_keyframes_.pop_front();
  }
  const track::MappingStatus mapping{mapping_stage_->idle() && delayed_keyframes_.empty(),
                                     mapping_stage_->queued() + delayed_keyframes_.size()};
  const track::TrackOutcome outcome = tracker_.track(frame, mapping);
  times_.add("track", watch.elapsed_ms());
  times_.add("track_lock", tracker_.last_lock().held_ms);
  times_.add("track_lock_wait", tracker_.last_lock().waited_ms);
  spdlog::debug("frame {}: {} features, {} culled{}, {} tracked inliers, {}{}", data.index,
                frame.features.size(), frame.culled,
                culled.result.ego_motion_rejected ? " (motion-check camera fit rejected)" : "",
                outcome.inliers, track::to_string(outcome.state),
                outcome.new_keyframe != map::kNoKeyframe ? ", keyframe" : "");
  if (outcome.new_keyframe != map::kNoKeyframe) {
    ++keyframes_created_;
    if (!mapping.idle) mapping_stage_->interrupt_ba();
    if (deterministic_ && latency > 0) {
      delayed_keyframes_.emplace_back(data.index + latency, outcome.new_keyframe);
    } else {
      mapping_stage_->submit(outcome.new_keyframe);
    }
    artifacts_.on_keyframe(outcome.new_keyframe, data);
  }
  times_.add("frame", frame_watch.elapsed_ms());
  ++frames_;
  FrameReport report{outcome.state,
                     outcome.inliers,
                     frame.features.size(),
                     frame.culled,
                     outcome.new_keyframe != map::kNoKeyframe,
                     outcome.new_keyframe,
                     std::nullopt,
                     std::move(culled_points)};
  if (outcome.state == track::TrackingState::Ok && frame.has_pose) report.T_wc = frame.T_cw.inverse();
  return report;
}

void SlamSystem::finish() {
  if (finished_) return;
  finished_ = true;
  for (const auto& [due, kf] : delayed_keyframes_) mapping_stage_->submit(kf);
  delayed_keyframes_.clear();
  mapping_stage_->stop();  // drains into the loop stage
  if (loop_stage_) loop_stage_->stop();
  if (closer_) closer_->flush();
}

nlohmann::json SlamSystem::write_artifacts() {
  map::MapView view = map_.view();
  return artifacts_.write(view);
}

std::vector<io::StampedPose> SlamSystem::trajectory() {
  map::MapView view = map_.view();
  std::vector<io::StampedPose> out;
  for (const auto& p : tracker_.trajectory().resolve(view)) out.push_back(to_stamped(p.stamp, p.T_wc));
  return out;
}

std::vector<std::pair<double, std::uint32_t>> SlamSystem::trajectory_maps() {
  map::MapView view = map_.view();
  std::vector<std::pair<double, std::uint32_t>> out;
  for (const auto& p : tracker_.trajectory().resolve(view)) out.emplace_back(p.stamp, map::to_int(p.map_id));
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

std::vector<Eigen::Vector3f> SlamSystem::map_point_positions(std::size_t max) {
  std::vector<Eigen::Vector3f> all;
  {
    map::MapView view = map_.view();
    all.reserve(view.points().size());
    for (const auto& [id, p] : view.points())
      if (!p.bad) all.push_back(p.position.cast<float>());
  }
  if (max == 0 || all.size() <= max) return all;
  std::vector<Eigen::Vector3f> out;
  out.reserve(max);
  for (std::size_t k = 0; k < max; ++k) out.push_back(all[k * all.size() / max]);
  return out;
}

std::vector<loop::LoopClosure> SlamSystem::loop_closures() const {
  return closer_ ? closer_->stats().closures : std::vector<loop::LoopClosure>{};
}

nlohmann::json SlamSystem::statistics() {
  nlohmann::json j;
  j["frames"] = frames_;
  j["tracked_frames"] = tracker_.trajectory().size();
  j["lost_frames"] = tracker_.lost_frames();
  j["relocalizations"] = tracker_.relocalizations();
  {
    const track::RelocalizationStats& r = tracker_.relocalization_stats();
    nlohmann::json reloc = {{"attempts", r.attempts},
                            {"candidates_tried", r.candidates_tried},
                            {"poses_found", r.poses_found},
                            {"accepted", r.accepted},
                            {"rejected_by_consistency", r.rejected_by_consistency},
                            {"ambiguous", r.ambiguous},
                            {"verify_frames", config_.tracker.relocalization_verify_frames},
                            {"database", reloc_index_ ? "bow" : "recent-keyframes"}};
    if (reloc_index_) {
      const RelocalizationIndexStats s = reloc_index_->stats();
      reloc["database_keyframes"] = reloc_index_->size();
      reloc["database_filed"] = s.filed;
      reloc["database_erased"] = s.erased;
      reloc["database_queries"] = s.queries;
    }
    j["relocalization"] = reloc;
  }
  j["pose_guard"] = {{"jumps", tracker_.guard_stats().jumps},
                     {"resolved", tracker_.guard_stats().resolved},
                     {"keyframes_vetoed", tracker_.guard_stats().keyframes_vetoed},
                     {"keyframes_despite_jump", tracker_.guard_stats().keyframes_despite_jump}};
  j["motion_breaks"] = tracker_.motion_breaks();
  {
    const LocalBASummary ba = mapping_stage_->ba_summary();
    j["local_ba"] = {{"solved", ba.solved},
                     {"aborted", ba.aborted},
                     {"dropped", ba.dropped},
                     {"held_keyframes", ba.held_keyframes},
                     {"largest_keyframe_move_cm", 100.0 * ba.largest_keyframe_move_m},
                     {"moves_over_1cm", ba.moves_over_1cm},
                     {"moves_over_3cm", ba.moves_over_3cm},
                     {"moves_over_10cm", ba.moves_over_10cm}};
  }
  j["new_points_moving"] = tracker_.new_points_moving();
  j["still_people_reserve"] = {
      {"releases", tracker_.reserve_stats().releases},
      {"points", tracker_.reserve_stats().points},
      {"tracker_releases", tracker_.reserve_stats().tracker_releases},
      {"tracker_releases_tracked", tracker_.reserve_stats().tracker_releases_tracked}};
  j["subpixel"] = {{"enabled", config_.tracker.subpixel.enabled},
                   {"frames", tracker_.subpixel_stats().frames},
                   {"candidates", tracker_.subpixel_stats().candidates},
                   {"refined", tracker_.subpixel_stats().refined},
                   {"aligned_only_solves", tracker_.subpixel_stats().aligned_only_solves}};
  j["keyframes_created"] = keyframes_created_;
  j["keyframe_policy"] = tracker_.policy().name();
  j["keyframe_rules"] = nlohmann::json::object();  // how often each rule of the policy fired
  for (const auto& [rule, count] : tracker_.policy().rule_counts()) j["keyframe_rules"][rule] = count;
  j["dynamic_mode"] = culling_.mode();
  j["detector_model"] = culling_.model_file().string();  // empty when no detector ran
  j["culled_features_total"] = culled_total_;
  j["refilled_features_total"] = refilled_total_;
  j["ego_motion_rejected_frames"] = ego_motion_rejected_;
  if (culling_score_) j["culling_score"] = culling_score_->to_json();
  j["culled_features_per_frame"] =
      frames_ > 0 ? static_cast<double>(culled_total_) / static_cast<double>(frames_) : 0.0;
  {
    map::MapView view = map_.view();
    j["keyframes"] = view.live_keyframes();
    j["map_points"] = view.live_points();
    // Atlas: maps started (the first included), merges, and the trajectory's frames per map as they are
    // now (a map never merged keeps its own frame: its frames are flagged, not silently mixed).
    const track::AtlasStats& a = tracker_.atlas_stats();
    j["maps"] = a.maps_created;
    j["merges"] = a.merges;
    j["merge_searches"] = a.merge_searches;
    j["merge_candidates"] = a.merge_candidates;
    j["merges_rejected"] = a.merges_rejected;
    j["young_maps_dropped"] = a.young_maps_dropped;
    j["frames_withdrawn"] = a.frames_withdrawn;
    std::map<std::uint32_t, std::size_t> per_map;
    for (const auto& p : tracker_.trajectory().resolve(view)) ++per_map[map::to_int(p.map_id)];
    nlohmann::json frames = nlohmann::json::object();
    for (const auto& [m, n] : per_map) frames[std::to_string(m)] = n;
    j["frames_per_map"] = frames;
    nlohmann::json unmerged = nlohmann::json::array();
    for (map::MapId m : tracker_.open_maps()) {
      if (m != map::kFirstMap) unmerged.push_back(map::to_int(m));
    }
    j["unmerged_maps"] = unmerged;
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
    j["loops_rejected_by_drift"] = ls.rejected_by_drift;
    j["loops_rejected_by_neighbours"] = ls.rejected_by_neighbours;
    j["loops_closed"] = ls.loops_closed;
    j["loop_candidates"] = ls.candidates;
    j["loop_queries"] = ls.queries;
    j["loop_detection_ms_total"] = ls.detection_ms_total;
    j["loop_bow_ms_total"] = ls.bow_ms_total;
    if (closer_->needs_global_descriptors()) {
      j["loop_global_descriptor_ms_total"] = ls.global_ms_total;
      j["loop_candidates_vetoed_by_descriptor"] = ls.vetoed_by_descriptor;
      j["loop_candidates_undescribed"] = ls.undescribed_candidates;
      j["place_model_load_ms"] = place_model_load_ms_;
    }
    j["loop_verifications"] = ls.verifications;
    j["loop_verification_ms_total"] = ls.verification_ms_total;
    j["loop_verification_lock_ms_total"] = ls.verification_lock_ms_total;
    j["loop_correction_ms_total"] = ls.correction_ms_total;
    j["loop_correction_lock_ms_total"] = ls.correction_lock_ms_total;
    j["loop_pose_graph_ms_total"] = ls.pose_graph_ms_total;
    j["global_ba_runs"] = ls.global_ba_runs;
    j["vocabulary_words"] = vocabulary_words_;
    j["vocabulary_load_ms"] = vocabulary_load_ms_;
  }
  j["peak_rss_mib"] = peak_rss_mib();
  j["deterministic"] = deterministic_;
  for (const auto& [k, v] : map_file_stats_.items()) j[k] = v;
  if (j.contains("map_loaded")) {
    const auto first = tracker_.first_relocalization_frame();
    j["map_loaded"]["first_relocalization_frame"] = first ? nlohmann::json(*first) : nlohmann::json(nullptr);
  }
  return j;
}

}  // namespace sp::pipeline
