#pragma once
// Loop closing over the map: detection (BoW per keyframe or per keyframe sequence), RGB-D geometric
// verification (descriptor matches -> 3-D/3-D RANSAC SE(3) -> projection matches -> pose refinement),
// correction (fuse the two sides, pose graph over the essential graph), and a global bundle
// adjustment in a background thread that tracking never waits for and a newer loop aborts.
#include <atomic>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>

#include "stillpoint/common/config_reader.hpp"
#include "stillpoint/loop/drift_limit.hpp"
#include "stillpoint/loop/loop_detector.hpp"
#include "stillpoint/loop/loop_verifier.hpp"
#include "stillpoint/loop/vocabulary.hpp"
#include "stillpoint/map/keyframe_hold.hpp"
#include "stillpoint/map/map.hpp"
#include "stillpoint/optimize/bundle_adjustment.hpp"
#include "stillpoint/tracking/frame.hpp"

namespace sp::loop {

struct LoopClosingConfig {
  std::string detector = "bow-keyframe";  // off | bow-keyframe | bow-sequence | netvlad
  // ParC_NetVLAD weights for the netvlad detector; relative paths: from the project root.
  std::string place_model = "models/parc_netvlad/parc_netvlad_small.pt";
  std::string vocabulary = "data/vocab/stillpoint_orb.spv";  // relative paths: from the project root
  LoopDetectorParams detection;
  std::size_t min_keyframes = 10;   // no detection before the map has this many keyframes
  LoopVerifierConfig verification;  // geometric verification of a candidate (same YAML section)
  bool global_ba = true;            // run a global BA after each closed loop (background thread)
  int global_ba_iterations = 10;
  static LoopClosingConfig from_yaml(const ConfigReader& r);
};

// One closed loop, as the benchmark checks it against ground truth.
struct LoopClosure {
  double query_stamp = 0, match_stamp = 0;
  geo::SE3 T_query_match;  // the verified relative pose (camera query <- camera match)
  int inliers = 0;
};

struct LoopClosingStats {
  std::size_t keyframes = 0;
  std::size_t candidates = 0;              // candidates from the detector (before verification)
  std::size_t loops_detected = 0;          // candidates that passed geometric verification
  std::size_t loops_closed = 0;            // corrections applied
  std::size_t rejected_by_drift = 0;       // verified geometrically, but moved further than drift allows
  std::size_t rejected_by_neighbours = 0;  // the query's neighbours did not confirm the loop pose
  std::size_t verifications = 0;           // candidates that reached geometric verification
  double verification_ms_total = 0;        // geometric verification, copying the evidence included
  double verification_lock_ms_total = 0;   // of which the map lock was held (copy in, counters out)
  std::size_t queries = 0;                 // database queries made by the detector
  std::size_t vetoed_by_descriptor = 0;    // hybrid detector: BoW candidates dropped by descriptor distance
  std::size_t undescribed_candidates = 0;  // hybrid detector: candidates passed on unranked (no descriptor)
  double detection_ms_total = 0;           // candidate search in the database (not BoW, not verification)
  double bow_ms_total = 0;                 // BoW conversion of the keyframes
  double global_ms_total = 0;              // global (ParC_NetVLAD) descriptors of the keyframes
  double correction_ms_total = 0;          // loop corrections: move, fusion, pose graph, points
  double correction_lock_ms_total = 0;     // of which the map lock was held (the pose graph is solved off it)
  double pose_graph_ms_total = 0;          // pose-graph solves
  std::size_t global_ba_runs = 0;
  std::size_t global_ba_aborted = 0;
  std::vector<LoopClosure> closures;
};

class LoopCloser {
 public:
  LoopCloser(map::Map& map, LoopClosingConfig config, std::shared_ptr<const Vocabulary> vocabulary,
             geo::CameraIntrinsics camera, track::DepthModel depth, map::ScalePyramid pyramid,
             bool deterministic);
  ~LoopCloser();
  LoopCloser(const LoopCloser&) = delete;
  LoopCloser& operator=(const LoopCloser&) = delete;

  // The netvlad detector's keyframe description (an image -> L2-normalised descriptor), provided by the
  // integrator so this module does not depend on the network library. Set before the first process().
  using GlobalDescriber = std::function<Eigen::VectorXf(const cv::Mat& bgr)>;
  void set_global_describer(GlobalDescriber describe) { describe_ = std::move(describe); }
  [[nodiscard]] bool needs_global_descriptors() const {
    return detector_ && detector_->uses_global_descriptors();
  }

  // Called on the loop-closing thread with each keyframe's BoW vector once the detector has filed it
  // (before verification), so other users of the vector (the relocalisation database) need not
  // compute it again. Set before the first process().
  using KeyframeFiled = std::function<void(map::KeyframeId, const BowVector&)>;
  void set_keyframe_filed(KeyframeFiled filed) { filed_ = std::move(filed); }
  // Forgets keyframes the map has culled (any thread): they are no longer loop candidates.
  void erase_keyframes(const std::vector<map::KeyframeId>& keyframes);

  // Handles one new keyframe (called in keyframe order by the loop-closing stage).
  void process(map::KeyframeId keyframe);
  // Files the keyframes of a loaded map (BoW already computed, in id order) without detection, so
  // new keyframes can close loops against them; with netvlad or hybrid their thumbnails are described
  // here (set_global_describer first). Call before the first process().
  void add_existing_keyframes(const std::vector<KeyframeInfo>& keyframes);
  // End of run: queries what the detector still holds (the open sequence), then waits for a
  // running global BA.
  void flush();
  // Waits for a running global BA.
  void finish();
  [[nodiscard]] LoopClosingStats stats() const;
  [[nodiscard]] bool enabled() const { return detector_ != nullptr; }

  // A loop that passed geometric verification. It holds its query and match keyframes against
  // culling until correct() has used them (verification and correction take separate map views).
  struct VerifiedLoop {
    map::KeyframeId query = map::kNoKeyframe, match = map::kNoKeyframe;
    geo::SE3 T_query_w;  // corrected pose of the query keyframe
    int inliers = 0;
    LoopClosure closure;  // what the benchmark checks against ground truth
    map::KeyframeHold hold;
  };
  // Geometric verification of one candidate pair (the steps of process(), usable on their own): the
  // evidence is copied under a short view and LoopVerifier runs with the map lock free; nullopt when
  // rejected or when local mapping culled either keyframe meanwhile.
  std::optional<VerifiedLoop> verify(map::KeyframeId query, map::KeyframeId match);
  // Corrects the map for a verified loop (fusion, pose graph, points, then a global BA if configured)
  // and releases its keyframes; false when the query was culled meanwhile (not possible while held).
  bool correct(VerifiedLoop loop);

 private:
  void handle_candidates(const std::vector<LoopCandidate>& candidates, map::KeyframeId kid);
  void start_global_ba(std::uint64_t changes_at_start);
  void run_global_ba(std::uint64_t changes_at_start);

  map::Map& map_;
  LoopClosingConfig config_;
  std::shared_ptr<const Vocabulary> vocabulary_;
  geo::CameraIntrinsics camera_;
  track::DepthModel depth_;
  map::ScalePyramid pyramid_;
  bool deterministic_;
  LoopVerifier verifier_;
  std::unique_ptr<LoopDetector> detector_;
  GlobalDescriber describe_;
  KeyframeFiled filed_;
  map::KeyframeId last_loop_keyframe_;

  mutable std::mutex stats_mutex_;
  LoopClosingStats stats_;
  std::thread global_ba_thread_;
  std::atomic<bool> abort_global_ba_{false};
};

}  // namespace sp::loop
