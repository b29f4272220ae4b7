// libFuzzer target: dynsynth boxes.txt (dynamic/oracle_detections) and lookups by timestamp.
#include <cmath>
#include <cstdlib>
#include <limits>

#include "fuzz_util.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/dynamic/oracle_detections.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const auto file = sp::fuzz::scratch_file("boxes.txt");
  sp::fuzz::write_file(file, data, size);
  try {
    const auto boxes = sp::dyn::OracleDetections::load(file);
    for (double t :
         {-1e300, 0.0, 1341846056.0, 1e300, std::nan(""), std::numeric_limits<double>::infinity()}) {
      const auto d = boxes.at(t, 0, false, 0.02);
      for (const auto& det : d.items) {
        if (det.box.width <= 0 && std::isfinite(det.box.width)) std::abort();
      }
    }
  } catch (const sp::Error&) {
  }
  return 0;
}
