#include "stillpoint/pipeline/run_artifacts.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <ctime>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <unordered_set>

#include "stillpoint/common/atomic_file.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/common/timing.hpp"

namespace sp::pipeline {

namespace {

// CPU time of the calling thread: what we take from tracking, unlike wall time, which on a busy
// machine mostly measures preemption.
double thread_cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}

template <typename T>
void put_le(std::string& buf, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  if constexpr (std::endian::native == std::endian::big) std::reverse(bytes, bytes + sizeof(T));
  buf.append(bytes, sizeof(T));
}

PlyPoint make_point(const Eigen::Vector3d& p, const cv::Vec3b& bgr) {
  return {static_cast<float>(p.x()),
          static_cast<float>(p.y()),
          static_cast<float>(p.z()),
          bgr[2],
          bgr[1],
          bgr[0]};
}

void write_text(const std::filesystem::path& file, const std::string& text) {
  write_file_atomically(file, text);
}

}  // namespace

void write_ply(const std::filesystem::path& file, const std::vector<PlyPoint>& points,
               const std::string& comment) {
  std::string buf = "ply\nformat binary_little_endian 1.0\n";
  if (!comment.empty()) buf += "comment " + comment + "\n";
  buf += fmt::format(
      "element vertex {}\nproperty float x\nproperty float y\nproperty float z\n"
      "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n",
      points.size());
  buf.reserve(buf.size() + points.size() * 15);
  for (const PlyPoint& p : points) {
    put_le(buf, p.x);
    put_le(buf, p.y);
    put_le(buf, p.z);
    buf.push_back(static_cast<char>(p.r));
    buf.push_back(static_cast<char>(p.g));
    buf.push_back(static_cast<char>(p.b));
  }
  write_text(file, buf);
}

RunArtifacts::RunArtifacts(ArtifactOptions options, geo::CameraIntrinsics camera)
    : options_(std::move(options)), camera_(std::move(camera)) {
  options_.max_thumbnails = std::max<std::size_t>(options_.max_thumbnails, 1);
  options_.dense_step = std::max(options_.dense_step, 1);
  options_.thumbnail_width = std::max(options_.thumbnail_width, 16);
  // With a size hint the stride is right from the start; otherwise thin_thumbnails() doubles it.
  if (options_.expected_frames > 0)
    stride_ = std::max<std::size_t>(
        1, (options_.expected_frames + options_.max_thumbnails - 1) / options_.max_thumbnails);
  if (enabled()) {
    // A previous run in the same folder must not leave stale thumbnails behind.
    std::error_code ec;
    std::filesystem::remove_all(options_.out_dir / "culled", ec);
    std::filesystem::remove(options_.out_dir / "dense_cloud.ply", ec);
    jobs_ = std::make_unique<BoundedQueue<Job>>(8);
    writer_ = std::thread([this] {
      while (auto job = jobs_->pop()) run_job(*job);
    });
  }
}

RunArtifacts::~RunArtifacts() { stop_writer(); }

void RunArtifacts::stop_writer() {
  if (!writer_.joinable()) return;
  jobs_->close();
  writer_.join();
}

void RunArtifacts::submit(Job job) {
  if (writer_.joinable() && jobs_->push(std::move(job))) return;
  run_job(job);  // the writer has been stopped (write() was called): do it here
}

void RunArtifacts::on_frame(const io::FrameData& data, const std::vector<cv::KeyPoint>& keypoints,
                            const std::vector<bool>& dynamic, const std::vector<dyn::Detection>& boxes,
                            const std::vector<bool>& box_dynamic) {
  if (!enabled()) return;
  const double cpu_start = thread_cpu_ms();
  if (options_.dense_cloud) {
    pending_culled_.clear();
    pending_boxes_.clear();
    for (std::size_t i = 0; i < dynamic.size() && i < keypoints.size(); ++i)
      if (dynamic[i]) pending_culled_.push_back(keypoints[i].pt);
    for (std::size_t i = 0; i < boxes.size() && i < box_dynamic.size(); ++i)
      if (box_dynamic[i]) pending_boxes_.push_back(boxes[i].box);
  }
  if (data.index % stride_ == 0 && !data.bgr.empty()) {
    Thumbnail t{data.index, data.stamp, fmt::format("frame_{:06d}.jpg", data.index), keypoints.size(),
                static_cast<std::size_t>(std::count(dynamic.begin(), dynamic.end(), true))};
    Job job;
    job.file = t.file;
    job.bgr = data.bgr;
    job.keypoints = keypoints;
    job.dynamic = dynamic;
    job.boxes = boxes;
    job.box_dynamic = box_dynamic;
    submit(std::move(job));
    thumbnails_.push_back(std::move(t));
    thin_thumbnails();
  }
  const double ms = thread_cpu_ms() - cpu_start;
  tracking_ms_total_ += ms;
  tracking_ms_max_ = std::max(tracking_ms_max_, ms);
}

void RunArtifacts::run_job(Job& job) {
  const std::filesystem::path dir = options_.out_dir / "culled";
  std::error_code ec;
  if (job.kind == Job::Kind::Remove) {
    std::filesystem::remove(dir / job.file, ec);
    return;
  }
  if (job.kind == Job::Kind::Dense) {
    keep_dense(job);
    return;
  }
  try {
    const double s = static_cast<double>(options_.thumbnail_width) / job.bgr.cols;
    cv::Mat img;
    cv::resize(job.bgr, img, cv::Size(options_.thumbnail_width, std::max(1, cvRound(job.bgr.rows * s))), 0, 0,
               cv::INTER_AREA);
    const cv::Scalar red(40, 40, 255), green(60, 220, 60), amber(0, 190, 255);
    for (std::size_t i = 0; i < job.boxes.size(); ++i) {
      const bool moving = i < job.box_dynamic.size() && job.box_dynamic[i];
      const cv::Rect2f& b = job.boxes[i].box;
      cv::rectangle(img,
                    cv::Rect(cvRound(b.x * s), cvRound(b.y * s), cvRound(b.width * s), cvRound(b.height * s)),
                    moving ? red : amber, 1, cv::LINE_AA);
    }
    // Kept features first so the red (culled) ones stay visible on top.
    for (int pass = 0; pass < 2; ++pass) {
      for (std::size_t i = 0; i < job.keypoints.size(); ++i) {
        const bool is_dynamic = i < job.dynamic.size() && job.dynamic[i];
        if (is_dynamic != (pass == 1)) continue;
        const cv::Point c(cvRound(job.keypoints[i].pt.x * s), cvRound(job.keypoints[i].pt.y * s));
        cv::circle(img, c, is_dynamic ? 2 : 1, is_dynamic ? red : green, cv::FILLED, cv::LINE_AA);
      }
    }
    std::vector<uchar> jpeg;
    if (!cv::imencode(".jpg", img, jpeg, {cv::IMWRITE_JPEG_QUALITY, 80})) throw Error("JPEG encoding failed");
    std::filesystem::create_directories(dir);
    write_text(dir / job.file, std::string(jpeg.begin(), jpeg.end()));
  } catch (const std::exception& e) {
    // A missing thumbnail is noted by the report; it must never stop the run.
    spdlog::warn("thumbnail {} not written: {}", job.file, e.what());
  }
}

void RunArtifacts::thin_thumbnails() {
  while (thumbnails_.size() > options_.max_thumbnails) {
    stride_ *= 2;
    std::vector<Thumbnail> kept;
    for (Thumbnail& t : thumbnails_) {
      if (t.index % stride_ == 0) {
        kept.push_back(std::move(t));
      } else {
        Job job;
        job.kind = Job::Kind::Remove;
        job.file = t.file;
        submit(std::move(job));
      }
    }
    thumbnails_ = std::move(kept);
  }
}

void RunArtifacts::on_keyframe(map::KeyframeId id, const io::FrameData& data) {
  if (!enabled() || !options_.dense_cloud || data.depth.empty() || data.bgr.empty()) return;
  const double cpu_start = thread_cpu_ms();
  Job job;
  job.kind = Job::Kind::Dense;
  job.keyframe = id;
  job.bgr = data.bgr;
  job.depth = data.depth;
  job.culled_points = std::move(pending_culled_);
  job.dynamic_boxes = std::move(pending_boxes_);
  pending_culled_.clear();
  pending_boxes_.clear();
  submit(std::move(job));
  const double ms = thread_cpu_ms() - cpu_start;
  tracking_ms_total_ += ms;
  tracking_ms_max_ = std::max(tracking_ms_max_, ms);
}

void RunArtifacts::keep_dense(Job& job) {
  const int step = options_.dense_step;
  const cv::Size small((job.depth.cols + step - 1) / step, (job.depth.rows + step - 1) / step);
  DenseKeyframe kf;
  // Nearest-neighbour for depth: averaging across a depth edge would invent points in mid-air.
  cv::resize(job.depth, kf.depth, small, 0, 0, cv::INTER_NEAREST);
  cv::resize(job.bgr, kf.bgr, small, 0, 0, cv::INTER_AREA);
  kf.keep = cv::Mat(small, CV_8U, cv::Scalar(255));
  const double s = 1.0 / step;
  for (const cv::Rect2f& b : job.dynamic_boxes)
    cv::rectangle(
        kf.keep,
        cv::Rect(cvFloor(b.x * s), cvFloor(b.y * s), cvCeil(b.width * s) + 1, cvCeil(b.height * s) + 1),
        cv::Scalar(0), cv::FILLED);
  const int radius = std::max(1, cvCeil(options_.dynamic_margin_px * s));
  for (const cv::Point2f& p : job.culled_points)
    cv::circle(kf.keep, cv::Point(cvRound(p.x * s), cvRound(p.y * s)), radius, cv::Scalar(0), cv::FILLED);
  dense_[job.keyframe] = std::move(kf);
}

std::vector<PlyPoint> RunArtifacts::map_cloud(map::MapView& view) const {
  std::vector<PlyPoint> out;
  out.reserve(view.points().size());
  const cv::Vec3b fallback(200, 200, 200);
  for (const auto& [id, p] : view.points()) {
    if (p.bad) continue;
    // Colour: the pixel under the point's observation in its reference keyframe's thumbnail.
    cv::Vec3b colour = fallback;
    for (map::KeyframeId kf_id : {p.reference, p.first_keyframe}) {
      const auto obs = p.observations.find(kf_id);
      if (obs == p.observations.end()) continue;
      const map::Keyframe* kf = view.keyframe(kf_id);
      if (kf == nullptr || kf->thumbnail.empty() || obs->second < 0 ||
          static_cast<std::size_t>(obs->second) >= kf->features.keypoints.size())
        continue;
      const cv::Point2f uv = kf->features.keypoints[static_cast<std::size_t>(obs->second)].pt;
      const int x = std::clamp(cvRound(uv.x * kf->thumbnail.cols / camera_.width), 0, kf->thumbnail.cols - 1);
      const int y =
          std::clamp(cvRound(uv.y * kf->thumbnail.rows / camera_.height), 0, kf->thumbnail.rows - 1);
      colour = kf->thumbnail.at<cv::Vec3b>(y, x);
      break;
    }
    out.push_back(make_point(p.position, colour));
  }
  return out;
}

std::vector<PlyPoint> RunArtifacts::dense_cloud(map::MapView& view) const {
  std::vector<PlyPoint> out;
  if (dense_.empty()) return out;
  // Undistorted pixel centres of the subsampled grid, computed once for all keyframes.
  const cv::Size small = dense_.begin()->second.depth.size();
  const int step = options_.dense_step;
  std::vector<cv::Point2f> grid;
  grid.reserve(static_cast<std::size_t>(small.area()));
  for (int v = 0; v < small.height; ++v)
    for (int u = 0; u < small.width; ++u)
      grid.emplace_back(static_cast<float>(u * step), static_cast<float>(v * step));
  const std::vector<cv::Point2f> ideal = camera_.undistort(grid);

  struct VoxelHash {
    std::size_t operator()(const Eigen::Vector3i& k) const {
      return (static_cast<std::size_t>(k.x()) * 73856093u) ^ (static_cast<std::size_t>(k.y()) * 19349663u) ^
             (static_cast<std::size_t>(k.z()) * 83492791u);
    }
  };
  std::unordered_set<Eigen::Vector3i, VoxelHash> occupied;
  std::vector<map::KeyframeId> ids;
  for (const auto& [id, kf] : dense_) ids.push_back(id);
  std::sort(ids.begin(), ids.end());  // same output for the same run
  for (map::KeyframeId id : ids) {
    const map::Keyframe* kf = view.keyframe(id);
    if (kf == nullptr || kf->bad) continue;  // culled by local mapping: its view is covered by others
    const DenseKeyframe& d = dense_.at(id);
    if (d.depth.size() != small) continue;
    const geo::SE3 T_wc = kf->T_cw.inverse();
    for (int v = 0; v < small.height; ++v) {
      for (int u = 0; u < small.width; ++u) {
        const float z = d.depth.at<float>(v, u);
        if (!(z > 0.f) || d.keep.at<std::uint8_t>(v, u) == 0) continue;
        const cv::Point2f& px = ideal[static_cast<std::size_t>(v * small.width + u)];
        const Eigen::Vector3d p_w = T_wc * camera_.unproject({px.x, px.y}, z);
        if (options_.dense_voxel > 0) {
          const Eigen::Vector3i key = (p_w / options_.dense_voxel).array().floor().cast<int>();
          if (!occupied.insert(key).second) continue;
        }
        out.push_back(make_point(p_w, d.bgr.at<cv::Vec3b>(v, u)));
      }
    }
  }
  return out;
}

nlohmann::json RunArtifacts::write(map::MapView& view) {
  nlohmann::json j;
  if (!enabled()) return j;
  Stopwatch watch;
  stop_writer();  // every picked thumbnail is on disk before the index names it
  std::filesystem::create_directories(options_.out_dir);
  const auto map_points = map_cloud(view);
  write_ply(options_.out_dir / "map_points.ply", map_points, "StillPoint map points (SLAM world frame)");
  j["map_points_ply"] = map_points.size();
  if (options_.dense_cloud) {
    const auto dense = dense_cloud(view);
    write_ply(options_.out_dir / "dense_cloud.ply", dense,
              fmt::format(
                  "StillPoint dense cloud: keyframe depth every {} px, {} m voxels, dynamic regions removed",
                  options_.dense_step, options_.dense_voxel));
    j["dense_cloud_points"] = dense.size();
    j["dense_cloud_keyframes"] = dense_.size();
  }
  nlohmann::json frames = nlohmann::json::array();
  for (const Thumbnail& t : thumbnails_)
    frames.push_back({{"index", t.index},
                      {"stamp", t.stamp},
                      {"file", t.file},
                      {"features", t.features},
                      {"culled", t.culled}});
  if (!thumbnails_.empty()) {
    std::filesystem::create_directories(options_.out_dir / "culled");
    write_text(options_.out_dir / "culled" / "index.json",
               nlohmann::json{{"stride", stride_}, {"frames", frames}}.dump(2) + "\n");
  }
  j["culled_thumbnails"] = thumbnails_.size();
  j["tracking_thread_cpu_ms_total"] = tracking_ms_total_;
  j["tracking_thread_cpu_ms_max"] = tracking_ms_max_;
  j["write_ms"] = watch.elapsed_ms();
  return j;
}

}  // namespace sp::pipeline
