#include "stillpoint/pipeline/system_config.hpp"

namespace sp::pipeline {

PipelineConfig PipelineConfig::from_yaml(const ConfigReader& r) {
  PipelineConfig c;
  r.read("mapping_queue", c.mapping_queue, std::size_t{1}, std::size_t{1000});
  r.read("loop_queue", c.loop_queue, std::size_t{1}, std::size_t{1000});
  return c;
}

track::DepthModel depth_model_from_yaml(const ConfigReader& r) {
  track::DepthModel d;
  r.read("depth_min", d.depth_min, 0.0, 100.0);
  r.read("depth_max", d.depth_max, 0.1, 100.0);
  r.read("bf", d.bf, 1.0, 1000.0);
  r.read("close_depth", d.close_depth, 0.1, 100.0);
  if (d.depth_min >= d.depth_max) r.fail("depth_min", "must be below depth_max");
  return d;
}

SystemConfig SystemConfig::from_yaml(const ConfigReader& r) {
  SystemConfig c;
  c.orb = feat::OrbConfig::from_yaml(r.section("orb"));
  c.depth = depth_model_from_yaml(r.section("depth"));
  c.tracker = track::TrackerConfig::from_yaml(r.section("tracking"));
  c.mapping = mapping::LocalMappingConfig::from_yaml(r.section("local_mapping"));
  c.dynamic = DynamicConfig::from_yaml(r.section("dynamic"));
  c.loop = loop::LoopClosingConfig::from_yaml(r.section("loop_closing"));
  c.pipeline = PipelineConfig::from_yaml(r.section("pipeline"));
  return c;
}

SystemConfig SystemConfig::load(const std::filesystem::path& file) {
  const ConfigReader r = ConfigReader::from_file(file);
  SystemConfig c = from_yaml(r);
  r.finish();
  return c;
}

}  // namespace sp::pipeline
