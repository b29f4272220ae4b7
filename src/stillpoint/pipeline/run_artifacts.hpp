#pragma once
// What a run leaves behind for people rather than for the evaluation scripts: the map as a coloured
// point cloud (map_points.ply), optionally a dense cloud from keyframe depth with the culled dynamic
// regions cut out (dense_cloud.ply), and a handful of frames with their culled features drawn
// (culled/frame_NNNNNN.jpg + culled/index.json). `stillpoint report` turns them into a page.
//
// Cost on the tracking thread: on_frame() is a modulo test for most frames; for the picked frames
// (at most about `max_thumbnails`) it copies the keypoint list and hands the frame to a writer
// thread that resizes, draws, JPEG-encodes and writes it. With the dense cloud on, each new keyframe
// keeps a subsampled copy of its depth and colour (a few hundred kB at the default step).
#include <cstdint>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <thread>
#include <unordered_map>
#include <vector>

#include "stillpoint/common/bounded_queue.hpp"
#include "stillpoint/dynamic/detection.hpp"
#include "stillpoint/geometry/camera.hpp"
#include "stillpoint/io/frame.hpp"
#include "stillpoint/map/map.hpp"

namespace sp::pipeline {

struct ArtifactOptions {
  std::filesystem::path out_dir;    // empty: no artifacts at all
  std::size_t max_thumbnails = 24;  // culled-feature thumbnails kept, evenly spread over the run
  int thumbnail_width = 320;        // px
  std::size_t expected_frames = 0;  // the source's size hint; 0 = unknown (stride doubles as needed)
  bool dense_cloud = false;         // write dense_cloud.ply from keyframe depth
  int dense_step = 4;               // px, keep every dense_step-th pixel in x and y
  double dense_voxel = 0.01;        // m, one point per voxel (keyframes overlap heavily); 0 = off
  double dynamic_margin_px = 24;    // px around a culled feature that the dense cloud leaves out
};

// One coloured point as stored in our PLY files (float x y z, uchar red green blue).
struct PlyPoint {
  float x = 0, y = 0, z = 0;
  std::uint8_t r = 0, g = 0, b = 0;
};

// binary_little_endian 1.0 with one `vertex` element; written to a temporary file and renamed.
// Throws sp::Error when the file cannot be written.
void write_ply(const std::filesystem::path& file, const std::vector<PlyPoint>& points,
               const std::string& comment = "");

class RunArtifacts {
 public:
  RunArtifacts(ArtifactOptions options, geo::CameraIntrinsics camera);
  ~RunArtifacts();
  RunArtifacts(const RunArtifacts&) = delete;
  RunArtifacts& operator=(const RunArtifacts&) = delete;

  [[nodiscard]] bool enabled() const { return !options_.out_dir.empty(); }

  // Every frame, on the tracking thread, before the dynamic features are dropped. `keypoints` are the
  // raw (distorted) detections, `dynamic` flags them (empty when culling is off), `boxes` /
  // `box_dynamic` are the detections carried to this frame.
  void on_frame(const io::FrameData& data, const std::vector<cv::KeyPoint>& keypoints,
                const std::vector<bool>& dynamic, const std::vector<dyn::Detection>& boxes,
                const std::vector<bool>& box_dynamic);
  // The frame last passed to on_frame() became keyframe `id`.
  void on_keyframe(map::KeyframeId id, const io::FrameData& data);

  // Waits for the thumbnail writer, then writes map_points.ply, dense_cloud.ply (when enabled) and
  // culled/index.json; returns figures for stats.json. Safe to call more than once (the last call
  // wins; thumbnails picked after the first call are written on the calling thread).
  nlohmann::json write(map::MapView& view);

 private:
  struct Thumbnail {
    std::size_t index = 0;
    double stamp = 0;
    std::string file;
    std::size_t features = 0, culled = 0;
  };
  // Work for the writer thread, in order: draw and write a thumbnail, remove one (thinning), or
  // keep a keyframe's subsampled depth and colour for the dense cloud.
  struct Job {
    enum class Kind { Thumbnail, Remove, Dense } kind = Kind::Thumbnail;
    std::string file;  // name inside out_dir/culled
    cv::Mat bgr;       // shares the frame's pixels (frames are never modified after decoding)
    cv::Mat depth;     // idem (Dense)
    std::vector<cv::KeyPoint> keypoints;
    std::vector<bool> dynamic;
    std::vector<dyn::Detection> boxes;
    std::vector<bool> box_dynamic;
    map::KeyframeId keyframe = map::kNoKeyframe;  // Dense
    std::vector<cv::Point2f> culled_points;       // Dense: the frame's dynamic regions
    std::vector<cv::Rect2f> dynamic_boxes;
  };
  struct DenseKeyframe {
    cv::Mat depth;  // CV_32F, subsampled
    cv::Mat bgr;    // CV_8UC3, same size
    cv::Mat keep;   // CV_8U, 0 where the pixel lies in a culled dynamic region
  };

  void submit(Job job);
  void run_job(Job& job);
  void keep_dense(Job& job);
  void stop_writer();
  void thin_thumbnails();
  std::vector<PlyPoint> map_cloud(map::MapView& view) const;
  std::vector<PlyPoint> dense_cloud(map::MapView& view) const;

  ArtifactOptions options_;
  geo::CameraIntrinsics camera_;
  std::size_t stride_ = 1;
  std::vector<Thumbnail> thumbnails_;
  // Dynamic regions of the last frame, kept until we know whether it became a keyframe.
  std::vector<cv::Point2f> pending_culled_;
  std::vector<cv::Rect2f> pending_boxes_;
  std::unordered_map<map::KeyframeId, DenseKeyframe> dense_;  // filled by the writer thread
  std::unique_ptr<BoundedQueue<Job>> jobs_;
  std::thread writer_;
  double tracking_ms_total_ = 0;  // CPU time spent here by the tracking thread
  double tracking_ms_max_ = 0;
};

}  // namespace sp::pipeline
