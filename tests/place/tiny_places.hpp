#pragma once
// Tiny dynsynth-style `places` folders for training tests: each room is a blurred random panorama and
// view i is an 80×60 window shifted 6 px per step, the camera 0.2 m further along x. Neighbours overlap
// (positives look alike), so recall is learnable and not only chance.
#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

namespace sp::place::test {

// Writes <root>/<room>/{rgb/NNNNNN.jpg, poses.txt, scene.txt} for each room once (atomically: parallel
// tests may share the folder) and returns root.
inline std::filesystem::path write_tiny_places(const std::filesystem::path& root,
                                               const std::vector<std::string>& rooms, int views = 12) {
  namespace fs = std::filesystem;
  if (fs::exists(root)) return root;
  const fs::path tmp = root.string() + ".tmp" + std::to_string(getpid());
  for (const auto& room : rooms) {
    const fs::path dir = tmp / ("room_" + room);
    fs::create_directories(dir / "rgb");
    std::ofstream poses(dir / "poses.txt");
    std::ofstream(dir / "scene.txt") << room << "\n";
    cv::Mat pano(60, 80 + 6 * views, CV_8UC3);
    std::uint64_t seed = 7;
    for (const char c : room) seed = seed * 131 + static_cast<unsigned char>(c);
    cv::RNG rng(seed);
    rng.fill(pano, cv::RNG::UNIFORM, 0, 256);
    cv::GaussianBlur(pano, pano, cv::Size(0, 0), 2.0);
    cv::normalize(pano, pano, 0, 255, cv::NORM_MINMAX);
    for (int i = 0; i < views; ++i) {
      const std::string name = cv::format("rgb/%06d.jpg", i);
      cv::imwrite((dir / name).string(), pano(cv::Rect(6 * i, 0, 80, 60)));
      poses << name << " " << 0.2 * i << " 0 0 0 0 0 1\n";
    }
  }
  std::error_code ec;
  fs::rename(tmp, root, ec);  // fails harmlessly when another process got there first
  if (ec) fs::remove_all(tmp);
  return root;
}

}  // namespace sp::place::test
