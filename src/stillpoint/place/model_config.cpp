#include "stillpoint/place/model_config.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace sp::place {

ModelConfig ModelConfig::tiny() { return ModelConfig{}; }

ModelConfig ModelConfig::small() {
  ModelConfig c = scaled(tiny(), 0.25, 1.0 / 3.0);
  // 240×320 (the dynsynth frame size): the final map is 7×10 local features for NetVLAD, not 3×5.
  // Models keep the size they were trained at (model files store it).
  c.input_height = 240;
  c.input_width = 320;
  return c;
}

ModelConfig ModelConfig::scaled(const ModelConfig& base, double width_mult, double depth_mult) {
  ModelConfig c = base;
  for (int i = 0; i < 4; ++i) {
    c.widths[i] = std::max(8, static_cast<int>(std::lround(base.widths[i] * width_mult / 8.0)) * 8);
    c.depths[i] = std::max(1, static_cast<int>(std::lround(base.depths[i] * depth_mult)));
  }
  return c;
}

ModelConfig ModelConfig::from_yaml(const sp::ConfigReader& r) {
  std::string variant = "small";
  r.read_choice("variant", variant, {"tiny", "small"});
  ModelConfig c = variant == "tiny" ? tiny() : small();
  double wm = 1.0, dm = 1.0;
  r.read("width_multiplier", wm, 0.05, 2.0);
  r.read("depth_multiplier", dm, 0.1, 2.0);
  if (wm != 1.0 || dm != 1.0) c = scaled(c, wm, dm);
  r.read("parc", c.parc);
  r.read("cbam", c.cbam);
  r.read("clusters", c.clusters, 2, 512);
  r.read("input_height", c.input_height, 32, 2048);
  r.read("input_width", c.input_width, 32, 2048);
  r.read("drop_path", c.drop_path, 0.0, 0.5);
  return c;
}

std::string ModelConfig::summary() const {
  return fmt::format("depths {}-{}-{}-{} widths {}-{}-{}-{} parc {} cbam {} K {} input {}x{} dim {}",
                     depths[0], depths[1], depths[2], depths[3], widths[0], widths[1], widths[2], widths[3],
                     parc ? "on" : "off", cbam ? "on" : "off", clusters, input_width, input_height,
                     descriptor_dim());
}

}  // namespace sp::place
