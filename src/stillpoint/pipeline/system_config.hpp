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
  int mapping_nice = 0;           // niceness of the local-mapping thread (tracking keeps 0)
  int loop_nice = 0;              // niceness of the loop-closing thread
  // --deterministic only: a keyframe reaches local mapping this many frames after it was made, and
  // tracking sees mapping busy meanwhile, as on a threaded run whose mapper lags (0: at once).
  int deterministic_mapping_latency = 0;
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
  // Loads and validates a file; every key must be known. Relative resource paths (the keys in
  // kPathKeys) resolve against the file's folder when the file they name exists there (made absolute);
  // otherwise they stay relative and resolve later against the data folder (SystemOptions::project_root:
  // share/stillpoint or the source tree), so a copy of the shipped file still finds the shipped data.
  static SystemConfig load(const std::filesystem::path& file);
  // The same with overrides "section.key=value" (the CLI's --set) applied to the file's YAML first;
  // a value is YAML ("0.5", "true", "[person, dog]"). Malformed overrides are ConfigErrors. A relative
  // path given in an override is looked up from the working directory first, then as above.
  static SystemConfig load(const std::filesystem::path& file, const std::vector<std::string>& overrides);
};

// The configuration keys that name files: loop_closing.vocabulary, loop_closing.place_model, dynamic.model.
inline constexpr const char* kPathKeys[] = {"loop_closing.vocabulary", "loop_closing.place_model",
                                            "dynamic.model"};

// Makes each relative path key absolute against `dir` when the file exists there (see load()); keys in
// `skip` are left alone.
void resolve_relative_paths(SystemConfig& config, const std::filesystem::path& dir,
                            const std::vector<std::string>& skip = {});

track::DepthModel depth_model_from_yaml(const ConfigReader& r);

}  // namespace sp::pipeline
