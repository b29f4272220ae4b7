#include "stillpoint/io/fake_source.hpp"

#include <opencv2/core.hpp>
#include <utility>

namespace sp::io {

FakeSource::FakeSource(CameraConfig camera, std::vector<FrameData> frames, std::size_t skipped)
    : camera_(std::move(camera)),
      frames_(std::make_move_iterator(frames.begin()), std::make_move_iterator(frames.end())),
      total_(frames_.size()),
      skipped_(skipped) {}

void FakeSource::push(FrameData frame) {
  frames_.push_back(std::move(frame));
  ++total_;
}

std::optional<FrameData> FakeSource::next() {
  if (frames_.empty()) return std::nullopt;
  FrameData f = std::move(frames_.front());
  frames_.pop_front();
  ++served_;
  return f;
}

FrameData make_synthetic_frame(const CameraConfig& camera, std::size_t index, double stamp, double depth_m,
                               unsigned seed) {
  const int w = camera.intrinsics.width;
  const int h = camera.intrinsics.height;
  FrameData f;
  f.index = index;
  f.stamp = stamp;
  f.depth_stamp = stamp;
  f.bgr.create(h, w, CV_8UC3);
  cv::RNG rng(seed + 1);
  rng.fill(f.bgr, cv::RNG::UNIFORM, cv::Scalar::all(0), cv::Scalar::all(256));
  f.depth = cv::Mat(h, w, CV_32FC1, cv::Scalar(static_cast<float>(depth_m)));
  return f;
}

}  // namespace sp::io
