// libFuzzer target: the model configurations. The same bytes go through
//   - the detector config YAML (dynamic/detection.cpp, DetectorConfig::from_yaml, config/dynamic/),
//   - the ParC_NetVLAD model config YAML (place/model_config.cpp, torch-free, so no libtorch here),
//   - the Darknet .cfg reader behind DetectorConfig::for_model (the [net] width/height).
// Only sp::Error may escape; a configuration that loads must be usable by the code that builds the
// network from it (sizes in range, every dynamic class in the class table).
#include <cstdlib>

#include "fuzz_util.hpp"
#include "stillpoint/common/config_reader.hpp"
#include "stillpoint/common/error.hpp"
#include "stillpoint/dynamic/detection.hpp"
#include "stillpoint/place/model_config.hpp"

namespace {

void check_detector(const sp::dyn::DetectorConfig& c) {
  if (c.input_width < 32 || c.input_width > 4096 || c.input_height < 32 || c.input_height > 4096)
    std::abort();
  if (!(c.scale > 0) || !(c.conf_threshold >= 0 && c.conf_threshold <= 1)) std::abort();
  for (const auto& name : c.dynamic_classes) {
    if (sp::dyn::class_index(c.names(), name) < 0) std::abort();
  }
}

void check_place(const sp::place::ModelConfig& c) {
  for (int i = 0; i < 4; ++i) {
    if (c.depths[i] < 1 || c.widths[i] < 8 || c.widths[i] % 8 != 0) std::abort();
  }
  if (c.descriptor_dim() <= 0 || c.input_height < 32 || c.input_width < 32) std::abort();
  if (c.summary().empty()) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const auto cfg_file = sp::fuzz::scratch_file("model.cfg");
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    const auto r = sp::ConfigReader::from_string(text, "model.yaml");
    try {
      check_detector(sp::dyn::DetectorConfig::from_yaml(r));
    } catch (const sp::Error&) {
    }
    try {
      check_place(sp::place::ModelConfig::from_yaml(r));
    } catch (const sp::Error&) {
    }
    try {
      r.finish();
    } catch (const sp::Error&) {
    }
  } catch (const sp::Error&) {
  }
  // The same bytes as a Darknet .cfg: for_model reads the network input size from its [net] section.
  sp::fuzz::write_file(cfg_file, data, size);
  try {
    check_detector(sp::dyn::DetectorConfig::for_model(cfg_file));
  } catch (const sp::Error&) {
  }
  return 0;
}
