#pragma once
// The whole system's configuration: one typed struct per module, loaded from one YAML file and
// validated on load (unknown keys, missing keys and out-of-range values name the file and line).
#include <filesystem>
#include <string>
#include <vector>

#include "stillpoint/common/config_reader.hpp"
#include "stillpoint/features/orb_extractor.hpp"
#include "stillpoint/loop/loop_closer.hpp"
#include "stillpoint/mapping/local_mapper.hpp"
#include "stillpoint/pipeline/dynamic_culling.hpp"
#include "stillpoint/tracking/frame.hpp"
#include "stillpoint/tracking/tracker.hpp"

namespace sp::pipeline {

struct PipelineConfig {
  std::size_t mapping_queue = 8;  // keyframes waiting for local mapping
  std::size_t loop_queue = 16;    // keyframes waiting for loop closing
  static PipelineConfig from_yaml(const ConfigReader& r);
};

struct SystemConfig {
  feat::OrbConfig orb;
  track::DepthModel depth;
  track::TrackerConfig tracker;
  mapping::LocalMappingConfig mapping;
  DynamicConfig dynamic;
  loop::LoopClosingConfig loop;
  PipelineConfig pipeline;

  static SystemConfig from_yaml(const ConfigReader& r);
  // Loads and validates a file; every key must be known.
  static SystemConfig load(const std::filesystem::path& file);
  // The same with overrides "section.key=value" (the CLI's --set) applied to the file's YAML first;
  // a value is YAML ("0.5", "true", "[person, dog]"). Malformed overrides are ConfigErrors.
  static SystemConfig load(const std::filesystem::path& file, const std::vector<std::string>& overrides);
};

track::DepthModel depth_model_from_yaml(const ConfigReader& r);

}  // namespace sp::pipeline
