// Derives the bounds of tests/dynamic/test_sequences.cpp from the data (not a test: it prints figures
// and checks nothing). The statistics the tests assert on are computed on disjoint windows of the same
// data, each with a fresh filter: dynsynth frames 30-69, 70-109, 110-149 (the tests use 30-149) and
// 60-frame windows of the pedestrian video (the test uses frames 0-59). A pooled ratio over several
// windows is a weighted mean of the windows' ratios, so the lowest window value is what the data
// itself allows the test's figure to fall to; the tests assert that, rounded down to 0.01.
//   motion_check_sweep <shared dir (../shared)> [video windows=10]
#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

#include "../sequence_score.hpp"

namespace {

using namespace sp::dyn;
using namespace sp::dyn::score;

struct Range {
  double lo = 1e9, hi = -1e9;
  void add(double v) {
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
};

void dynsynth(const fs::path& shared) {
  const fs::path seq = shared / "data/dynsynth/office_a_walking_xyz_150";
  const fs::path models = shared / "models";
  struct Case {
    const char* name;
    CullMode mode;
    Boxes boxes;
  };
  const Case cases[] = {{"oracle boxes + flow", CullMode::kDetectorFlow, Boxes::kOracle},
                        {"oracle boxes, detector only", CullMode::kDetectorOnly, Boxes::kOracle},
                        {"yolox + flow", CullMode::kDetectorFlow, Boxes::kYolox},
                        {"yolox, detector only", CullMode::kDetectorOnly, Boxes::kYolox},
                        {"flow only", CullMode::kFlowOnly, Boxes::kNone}};
  for (const auto& c : cases) {
    Range precision, recall, base;
    for (std::size_t first : {30, 70, 110}) {
      const Score s = run_sequence(seq, models, c.mode, c.boxes, first, first + 40);
      precision.add(s.precision());
      recall.add(s.recall_moving());
      base.add(s.base_rate());
    }
    const Score all = run_sequence(seq, models, c.mode, c.boxes, 30);
    std::printf(
        "== %s: windows precision %.3f-%.3f, recall(moving) %.3f-%.3f, base rate %.3f-%.3f; frames 30-149: "
        "precision %.3f recall(moving) %.3f base rate %.3f, moving keypoints %ld\n\n",
        c.name, precision.lo, precision.hi, recall.lo, recall.hi, base.lo, base.hi, all.precision(),
        all.recall_moving(), all.base_rate(), all.moving_total);
  }
}

void video(const fs::path& shared, int windows) {
  const fs::path file = shared / "data/people/opencv_vtest.avi";
  const fs::path model = shared / "models/yolo-fastest-1.1.cfg";
  Range boxes, rate, bg_static, still;
  int still_dynamic = 0;
  for (int w = 0; w < windows; ++w) {
    const VideoScore v = run_video(file, model, static_cast<std::size_t>(w) * 60, 60);
    if (!v.opened || v.frames < 60) break;
    boxes.add(v.boxes);
    rate.add(v.box_rate());
    bg_static.add(v.bg_static());
    still.add(v.still_boxes);
    still_dynamic += v.still_dynamic;
  }
  std::printf(
      "== vtest 60-frame windows: person boxes %.0f-%.0f, dynamic share %.3f-%.3f, background static "
      "%.3f-%.3f, control boxes %.0f-%.0f, control boxes judged dynamic in all windows: %d\n",
      boxes.lo, boxes.hi, rate.lo, rate.hi, bg_static.lo, bg_static.hi, still.lo, still.hi, still_dynamic);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: motion_check_sweep <shared dir> [video windows=10]\n");
    return 2;
  }
  const fs::path shared = argv[1];
  dynsynth(shared);
  video(shared, argc > 2 ? std::stoi(argv[2]) : 10);
  return 0;
}
