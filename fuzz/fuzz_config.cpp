// libFuzzer target: YAML configuration through sp::ConfigReader (from text and from a file), the
// camera config (every key typed and range-checked; from a file also the ORB-SLAM2/3 and stella_vslam
// layouts load_camera_config recognises) and generic section/read/finish use as the system config
// does. Only sp::Error may escape.
#include <cstdlib>

#include "fuzz_util.hpp"
#include "stillpoint/common/config_reader.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/io/camera_config.hpp"

namespace {

void exercise(const sp::ConfigReader& r) {
  try {
    const auto c = sp::io::CameraConfig::from_yaml(r);
    if (c.intrinsics.width < 1 || !(c.depth_max > c.depth_min)) std::abort();
    r.finish();
  } catch (const sp::Error&) {
  }
  try {
    double d = 1;
    int i = 2;
    std::string s = "off";
    bool b = false;
    std::size_t n = 3;
    const sp::ConfigReader sec = r.section("tracking");
    sec.read("value", d, -1e9, 1e9);
    sec.read("count", i, -100, 100);
    sec.read("flag", b);
    sec.read<std::size_t>("size", n, 0, 1000);
    r.read_choice("mode", s, {"off", "flow", "oracle"});
    const sp::ConfigReader nested = sec.section("inner");
    nested.read("x", d);
    r.finish();
  } catch (const sp::Error&) {
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const auto file = sp::fuzz::scratch_file("config.yaml");
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    exercise(sp::ConfigReader::from_string(text, "fuzz.yaml"));
  } catch (const sp::Error&) {
  }
  sp::fuzz::write_file(file, data, size);
  try {
    exercise(sp::ConfigReader::from_file(file));
  } catch (const sp::Error&) {
  }
  try {
    const auto c = sp::io::load_camera_config(file);  // any camera format
    if (c.intrinsics.width < 1 || !(c.intrinsics.fx > 0) || !(c.depth_factor > 0)) std::abort();
  } catch (const sp::Error&) {
  }
  return 0;
}
