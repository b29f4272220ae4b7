// Relative file paths in a configuration YAML resolve against that YAML's folder; paths the folder does
// not hold stay relative for the data folder (so a copy of the shipped file still finds the shipped
// vocabulary and detector); --set paths are the user's, from the working directory.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "stillpoint/pipeline/system_config.hpp"

namespace sp::pipeline {
namespace {

namespace fs = std::filesystem;

fs::path scratch(const std::string& name) {
  const fs::path d = fs::path(SP_TEST_TMP_DIR) / "config_paths" / name;
  fs::remove_all(d);
  fs::create_directories(d / "models");
  return d;
}

TEST(ConfigPaths, RelativeToTheYamlFolderWhenThere) {
  const fs::path d = scratch("yaml_folder");
  std::ofstream(d / "models" / "mine.onnx") << "x";
  std::ofstream(d / "my.spv") << "x";
  std::ofstream(d / "system.yaml") << "dynamic:\n  model: models/mine.onnx\n"
                                      "loop_closing:\n  vocabulary: my.spv\n"
                                      "  place_model: models/parc_netvlad/parc_netvlad_small.pt\n";
  const SystemConfig c = SystemConfig::load(d / "system.yaml");
  EXPECT_EQ(fs::path(c.dynamic.model), fs::absolute(d / "models" / "mine.onnx").lexically_normal());
  EXPECT_EQ(fs::path(c.loop.vocabulary), fs::absolute(d / "my.spv").lexically_normal());
  // Not beside the YAML: left for the data folder (SystemOptions::project_root).
  EXPECT_EQ(c.loop.place_model, "models/parc_netvlad/parc_netvlad_small.pt");
}

TEST(ConfigPaths, ShippedFileCopiedElsewhereStillNamesTheDataFolderFiles) {
  const fs::path d = scratch("copied");
  fs::copy_file(fs::path(SP_SOURCE_DIR) / "config" / "stillpoint.yaml", d / "copy.yaml");
  const SystemConfig c = SystemConfig::load(d / "copy.yaml");
  EXPECT_TRUE(fs::path(c.loop.vocabulary).is_relative());
  EXPECT_TRUE(fs::exists(fs::path(SP_SOURCE_DIR) / c.loop.vocabulary)) << c.loop.vocabulary;
  EXPECT_TRUE(fs::exists(fs::path(SP_SOURCE_DIR) / c.dynamic.model)) << c.dynamic.model;
}

TEST(ConfigPaths, SetOverridesResolveFromTheWorkingDirectory) {
  const fs::path d = scratch("overrides");
  const fs::path cwd = scratch("overrides_cwd");
  std::ofstream(cwd / "models" / "cli.onnx") << "x";
  std::ofstream(d / "models" / "cli.onnx") << "y";  // the same name beside the YAML must not win
  std::ofstream(d / "system.yaml") << "dynamic:\n  mode: flow\n";
  const fs::path before = fs::current_path();
  fs::current_path(cwd);
  const SystemConfig c = SystemConfig::load(d / "system.yaml", {"dynamic.model=models/cli.onnx"});
  fs::current_path(before);
  EXPECT_EQ(fs::path(c.dynamic.model), fs::absolute(cwd / "models" / "cli.onnx").lexically_normal());
}

}  // namespace
}  // namespace sp::pipeline
