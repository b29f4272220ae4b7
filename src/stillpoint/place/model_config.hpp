#pragma once
// Architecture of a ParC_NetVLAD model (torch-free, so the CLI and tests can use it cheaply).
#include <array>
#include <string>

#include "stillpoint/common/config_reader.hpp"

namespace sp::place {

struct ModelConfig {
  std::array<int, 4> depths{3, 3, 9, 3};         // blocks per stage (ConvNeXt-T)
  std::array<int, 4> widths{96, 192, 384, 768};  // channels per stage
  bool parc = true;                              // ParC blocks in the last 3 of stage 3 and last 1 of stage 4
  bool cbam = true;                              // CBAM between backbone and NetVLAD
  int clusters = 64;                             // NetVLAD K
  int input_height = 480;                        // px; images are resized to this
  int input_width = 640;                         // px
  double drop_path = 0.0;                        // max stochastic-depth rate [0, 0.5]
  double layer_scale_init = 1e-6;                // ConvNeXt layer-scale initial value

  // Full ConvNeXt-Tiny (the paper's definition).
  static ModelConfig tiny();
  // Width ×0.25, depths 1-1-3-1, 240×320 input: trainable on a 2-core CPU.
  static ModelConfig small();
  // Scales a base configuration (widths rounded to multiples of 8, depths at least 1).
  static ModelConfig scaled(const ModelConfig& base, double width_mult, double depth_mult);
  // Keys: variant (tiny|small), width_multiplier, depth_multiplier, parc, cbam, clusters,
  // input_height, input_width, drop_path.
  static ModelConfig from_yaml(const sp::ConfigReader& r);

  [[nodiscard]] int descriptor_dim() const { return clusters * widths[3]; }
  [[nodiscard]] std::string summary() const;
};

}  // namespace sp::place
