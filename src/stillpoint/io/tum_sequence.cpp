#include "stillpoint/io/tum_sequence.hpp"

#include <spdlog/spdlog.h>

#include <opencv2/imgcodecs.hpp>

#include "stillpoint/common/error.hpp"
#include "stillpoint/common/thread_priority.hpp"
#include "stillpoint/io/association.hpp"
#include "stillpoint/io/jpeg_reader.hpp"
#include "stillpoint/io/tum_text.hpp"

namespace sp::io {

namespace fs = std::filesystem;

TumSequenceOptions TumSequenceOptions::from_yaml(const ConfigReader& r) {
  TumSequenceOptions o;
  if (r.has("camera_file")) o.camera_file = fs::path(r.require<std::string>("camera_file"));
  r.read<std::size_t>("prefetch", o.prefetch, 1, 1024);
  r.read("max_difference", o.max_difference, 1e-4, 1.0);
  r.read("depth_offset", o.depth_offset, -1.0, 1.0);
  r.read<std::size_t>("max_frames", o.max_frames, 0, 100000000);
  r.read<std::size_t>("start_frame", o.start_frame, 0, 100000000);
  r.read("reader_nice", o.reader_nice, 0, 19);
  return o;
}

TumSequence::TumSequence(const fs::path& dir, const TumSequenceOptions& options)
    : dir_(dir), queue_(options.prefetch == 0 ? 1 : options.prefetch) {
  if (!fs::is_directory(dir_)) throw InputError(dir_.string(), 0, "sequence folder not found");
  const fs::path camera_file = options.camera_file.value_or(dir_ / "camera.yaml");
  if (!fs::exists(camera_file)) {
    throw InputError(camera_file.string(), 0,
                     "camera file not found (give one explicitly or put camera.yaml in the sequence folder)");
  }
  camera_ = load_camera_config(camera_file);
  load_entries(options);
  if (entries_.empty()) spdlog::warn("{}: no associated RGB-D frames", dir_.string());
  reader_ = std::thread([this, nice = options.reader_nice] {
    lower_this_thread_priority(nice, "sequence reader");
    reader_loop();
  });
}

TumSequence::~TumSequence() {
  stop_ = true;
  queue_.close();  // wakes a reader blocked on a full queue
  if (reader_.joinable()) reader_.join();
}

void TumSequence::load_entries(const TumSequenceOptions& options) {
  std::vector<Entry> all;
  const fs::path assoc = dir_ / "associations.txt";
  if (fs::exists(assoc)) {
    for (const auto& rec : read_tum_text(assoc, 4)) {
      double depth_stamp = 0;
      if (!parse_double(rec.columns[2], depth_stamp)) {
        throw InputError(assoc.string(), rec.line,
                         "depth timestamp '" + rec.columns[2] + "' is not a number");
      }
      all.push_back({all.size(), rec.stamp, depth_stamp, dir_ / rec.columns[1], dir_ / rec.columns[3]});
    }
  } else {
    const auto rgb = read_tum_file_list(dir_ / "rgb.txt");
    const auto depth = read_tum_file_list(dir_ / "depth.txt");
    std::vector<double> rs, ds;
    for (const auto& r : rgb) rs.push_back(r.stamp);
    for (const auto& d : depth) ds.push_back(d.stamp);
    for (const auto& [i, j] : associate(rs, ds, options.depth_offset, options.max_difference)) {
      all.push_back({all.size(), rgb[i].stamp, depth[j].stamp, dir_ / rgb[i].path, dir_ / depth[j].path});
    }
  }
  const std::size_t begin = std::min(options.start_frame, all.size());
  std::size_t end = all.size();
  if (options.max_frames != 0) end = std::min(end, begin + options.max_frames);
  entries_.assign(all.begin() + static_cast<std::ptrdiff_t>(begin),
                  all.begin() + static_cast<std::ptrdiff_t>(end));
}

std::optional<FrameData> TumSequence::load(const Entry& e) const {
  const auto& K = camera_.intrinsics;
  FrameData f;
  f.index = e.index;
  f.stamp = e.rgb_stamp;
  f.depth_stamp = e.depth_stamp;
  f.rgb_path = e.rgb.string();
  f.bgr = read_color_image(e.rgb.string());
  if (f.bgr.empty()) {
    spdlog::warn("skipping frame {}: cannot read colour image {}", e.index, e.rgb.string());
    return std::nullopt;
  }
  if (f.bgr.cols != K.width || f.bgr.rows != K.height) {
    spdlog::warn("skipping frame {}: colour image {} is {}x{}, the camera is {}x{}", e.index, e.rgb.string(),
                 f.bgr.cols, f.bgr.rows, K.width, K.height);
    return std::nullopt;
  }
  const cv::Mat raw = cv::imread(e.depth.string(), cv::IMREAD_UNCHANGED);
  if (raw.empty()) {
    spdlog::warn("skipping frame {}: cannot read depth image {}", e.index, e.depth.string());
    return std::nullopt;
  }
  if (raw.type() != CV_16UC1) {
    spdlog::warn("skipping frame {}: depth image {} is not 16-bit single channel", e.index, e.depth.string());
    return std::nullopt;
  }
  if (raw.size() != f.bgr.size()) {
    spdlog::warn("skipping frame {}: depth image {} is {}x{}, the colour image {}x{}", e.index,
                 e.depth.string(), raw.cols, raw.rows, f.bgr.cols, f.bgr.rows);
    return std::nullopt;
  }
  raw.convertTo(f.depth, CV_32F, 1.0 / camera_.depth_factor);
  // Readings outside the sensor's trusted range become invalid (0), like missing ones. One pass: the
  // reader shares the cores with tracking.
  const auto lo = static_cast<float>(camera_.depth_min), hi = static_cast<float>(camera_.depth_max);
  for (int r = 0; r < f.depth.rows; ++r) {
    auto* row = f.depth.ptr<float>(r);
    for (int c = 0; c < f.depth.cols; ++c)
      if (row[c] < lo || row[c] > hi) row[c] = 0.0f;
  }
  return f;
}

void TumSequence::reader_loop() {
  for (const auto& e : entries_) {
    if (stop_) break;
    std::optional<FrameData> frame;
    try {
      frame = load(e);
    } catch (const std::exception& ex) {  // a decoder may throw on a truncated file
      spdlog::warn("skipping frame {}: error reading {} / {}: {}", e.index, e.rgb.string(), e.depth.string(),
                   ex.what());
    }
    if (!frame) {
      ++skipped_;
      continue;
    }
    if (!queue_.push(std::move(*frame))) break;  // closed: the consumer is gone
  }
  queue_.close();
}

std::optional<FrameData> TumSequence::next() { return queue_.pop(); }

std::optional<fs::path> TumSequence::groundtruth_path() const {
  const fs::path gt = dir_ / "groundtruth.txt";
  if (fs::exists(gt)) return gt;
  return std::nullopt;
}

}  // namespace sp::io
