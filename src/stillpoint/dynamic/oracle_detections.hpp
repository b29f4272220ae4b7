#pragma once
// Ground-truth detections from a dynsynth boxes.txt ("timestamp id class x0 y0 x1 y1 moving"):
// an ideal detector for ablations and for scoring the motion check.
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "stillpoint/dynamic/detection.hpp"

namespace sp::dyn {

class OracleDetections {
 public:
  // Throws sp::InputError naming file:line on a malformed line, sp::Error when the file is missing.
  // Class names are looked up in `class_names` (COCO by default); unknown names get id -1.
  static OracleDetections load(const std::filesystem::path& boxes_txt,
                               const std::vector<std::string>& class_names = coco_class_names());

  // The boxes of the frame nearest to `stamp` (within max_dt seconds, else none). With
  // only_moving, boxes whose moving flag is 0 are left out. Scores are 1.
  [[nodiscard]] Detections at(double stamp, std::size_t frame_index = 0, bool only_moving = true,
                              double max_dt = 0.02) const;

  [[nodiscard]] std::size_t frame_count() const noexcept { return frames_.size(); }

 private:
  struct Box {
    int id = 0;
    Detection det;
    bool moving = false;
  };
  std::map<double, std::vector<Box>> frames_;
};

}  // namespace sp::dyn
