// The run-time data folder: $STILLPOINT_DATA_DIR, else share/stillpoint beside the binary or one of its
// parents (the install layout), never the compiled-in source tree.
#include <gtest/gtest.h>
#include <stdlib.h>

#include <filesystem>
#include <fstream>

#include "stillpoint/common/data_dir.hpp"
#include "stillpoint/common/error.hpp"

namespace sp {
namespace {

namespace fs = std::filesystem;

// A fake prefix: P/bin/tool, P/lib/x86_64-linux-gnu/libx.so and P/share/stillpoint/config/stillpoint.yaml.
fs::path make_prefix(const std::string& name) {
  const fs::path p = fs::path(SP_TEST_TMP_DIR) / "data_dir" / name;
  fs::remove_all(p);
  fs::create_directories(p / "bin");
  fs::create_directories(p / "lib" / "x86_64-linux-gnu");
  fs::create_directories(p / "share" / "stillpoint" / "config");
  std::ofstream(p / "bin" / "tool") << "";
  std::ofstream(p / "lib" / "x86_64-linux-gnu" / "libx.so") << "";
  std::ofstream(p / "share" / "stillpoint" / kDataMarker) << "orb: {}\n";
  return p;
}

// Restores the variable after the test.
class ScopedUnsetEnv {
 public:
  ScopedUnsetEnv() {
    if (const char* v = getenv("STILLPOINT_DATA_DIR")) saved_ = v;
    unsetenv("STILLPOINT_DATA_DIR");
  }
  ~ScopedUnsetEnv() {
    if (!saved_.empty()) {
      setenv("STILLPOINT_DATA_DIR", saved_.c_str(), 1);
    } else {
      unsetenv("STILLPOINT_DATA_DIR");
    }
  }
  ScopedUnsetEnv(const ScopedUnsetEnv&) = delete;
  ScopedUnsetEnv& operator=(const ScopedUnsetEnv&) = delete;

 private:
  std::string saved_;
};

TEST(DataDir, FoundBesideBinaryAndMultiarchLibrary) {
  const ScopedUnsetEnv env;
  const fs::path p = make_prefix("found");
  const fs::path expected = fs::canonical(p / "share" / "stillpoint");
  EXPECT_EQ(fs::canonical(resolve_data_dir(p / "bin" / "tool")), expected);
  EXPECT_EQ(fs::canonical(resolve_data_dir(p / "lib" / "x86_64-linux-gnu" / "libx.so")), expected);
  // Too far down: a limited walk does not reach it.
  EXPECT_FALSE(find_data_dir_near(p / "lib" / "x86_64-linux-gnu" / "libx.so", 1).has_value());
}

TEST(DataDir, MissingFolderIsAnErrorSayingWhatToSet) {
  const ScopedUnsetEnv env;
  const fs::path p = make_prefix("missing");
  fs::remove(p / "share" / "stillpoint" / kDataMarker);  // a share/stillpoint without data is no data folder
  // (The scratch folder lies inside the build tree, whose own share/stillpoint is 4 levels up.)
  EXPECT_FALSE(find_data_dir_near(p / "bin" / "tool", 2).has_value());
  try {
    (void)resolve_data_dir("/nonexistent/bin/tool");
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("STILLPOINT_DATA_DIR"), std::string::npos) << e.what();
  }
}

TEST(DataDir, EnvironmentVariableWinsAndIsChecked) {
  const ScopedUnsetEnv env;
  const fs::path a = make_prefix("env_a");
  const fs::path b = make_prefix("env_b");
  setenv("STILLPOINT_DATA_DIR", (b / "share" / "stillpoint").c_str(), 1);
  EXPECT_EQ(fs::canonical(resolve_data_dir(a / "bin" / "tool")), fs::canonical(b / "share" / "stillpoint"));
  setenv("STILLPOINT_DATA_DIR", (b / "bin").c_str(), 1);
  EXPECT_THROW((void)resolve_data_dir(a / "bin" / "tool"), Error);
}

// The build tree is laid out like a prefix (CMakeLists.txt links <build>/share/stillpoint to the
// source tree), so a test binary finds the source tree's data without a compiled-in path.
TEST(DataDir, BuildTreeHasTheInstallLayout) {
  const ScopedUnsetEnv env;
  const fs::path found = resolve_data_dir(current_executable());
  EXPECT_TRUE(fs::exists(found / "data" / "vocab" / "stillpoint_orb.spv")) << found;
  EXPECT_EQ(fs::canonical(found / "config"), fs::canonical(fs::path(SP_SOURCE_DIR) / "config"));
}

}  // namespace
}  // namespace sp
