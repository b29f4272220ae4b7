#include "stillpoint/pipeline/system_config.hpp"

#include <algorithm>
#include <system_error>

namespace sp::pipeline {

namespace {
std::string* path_field(SystemConfig& c, const std::string& key) {
  if (key == "loop_closing.vocabulary") return &c.loop.vocabulary;
  if (key == "loop_closing.place_model") return &c.loop.place_model;
  if (key == "dynamic.model") return &c.dynamic.model;
  return nullptr;
}
}  // namespace

void resolve_relative_paths(SystemConfig& config, const std::filesystem::path& dir,
                            const std::vector<std::string>& skip) {
  for (const char* key : kPathKeys) {
    if (std::find(skip.begin(), skip.end(), key) != skip.end()) continue;
    std::string* value = path_field(config, key);
    if (value == nullptr || value->empty()) continue;
    const std::filesystem::path p(*value);
    if (p.is_absolute()) continue;
    std::error_code ec;
    const std::filesystem::path candidate = std::filesystem::absolute(dir / p, ec).lexically_normal();
    if (!ec && std::filesystem::exists(candidate, ec)) *value = candidate.string();
  }
}

PipelineConfig PipelineConfig::from_yaml(const ConfigReader& r) {
  PipelineConfig c;
  r.read("mapping_queue", c.mapping_queue, std::size_t{1}, std::size_t{1000});
  r.read("loop_queue", c.loop_queue, std::size_t{1}, std::size_t{1000});
  r.read("mapping_nice", c.mapping_nice, 0, 19);
  r.read("loop_nice", c.loop_nice, 0, 19);
  r.read("deterministic_mapping_latency", c.deterministic_mapping_latency, 0, 1000);
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

SystemConfig SystemConfig::load(const std::filesystem::path& file,
                                const std::vector<std::string>& overrides) {
  if (overrides.empty()) return load(file);
  (void)ConfigReader::from_file(file);  // syntax errors in the file itself name its lines
  YAML::Node root = YAML::LoadFile(file.string());
  for (const std::string& o : overrides) {
    const auto eq = o.find('=');
    if (eq == std::string::npos || eq == 0) throw ConfigError("--set", 0, o, "expected section.key=value");
    const std::string path = o.substr(0, eq);
    YAML::Node value;
    try {
      value = YAML::Load(o.substr(eq + 1));
    } catch (const YAML::Exception& e) {
      throw ConfigError("--set", 0, path, std::string("value is not YAML: ") + e.what());
    }
    // Walk the dotted path, creating sections as needed (unknown keys are still caught below).
    std::vector<YAML::Node> chain{root};
    std::size_t start = 0;
    while (true) {
      const auto dot = path.find('.', start);
      const std::string key = path.substr(start, dot == std::string::npos ? std::string::npos : dot - start);
      if (key.empty()) throw ConfigError("--set", 0, path, "empty key in the dotted path");
      if (dot == std::string::npos) {
        chain.back()[key] = value;
        break;
      }
      YAML::Node next = chain.back()[key];
      if (!next.IsDefined() || next.IsNull()) chain.back()[key] = YAML::Node(YAML::NodeType::Map);
      chain.push_back(chain.back()[key]);
      start = dot + 1;
    }
  }
  YAML::Emitter out;
  out << root;
  const ConfigReader r = ConfigReader::from_string(out.c_str(), file.string() + " with --set");
  SystemConfig c = from_yaml(r);
  r.finish();
  // Paths typed on the command line are the user's: from the working directory; the file's own
  // paths from the file's folder.
  std::vector<std::string> from_file, from_command_line;
  for (const char* key : kPathKeys) {
    const bool overridden = std::any_of(overrides.begin(), overrides.end(), [key](const std::string& o) {
      return o.substr(0, o.find('=')) == key;
    });
    (overridden ? from_command_line : from_file).push_back(key);
  }
  resolve_relative_paths(c, std::filesystem::current_path(), from_file);
  resolve_relative_paths(c, file.parent_path(), from_command_line);
  return c;
}

SystemConfig SystemConfig::load(const std::filesystem::path& file) {
  const ConfigReader r = ConfigReader::from_file(file);
  SystemConfig c = from_yaml(r);
  r.finish();
  resolve_relative_paths(c, file.parent_path());
  return c;
}

}  // namespace sp::pipeline
