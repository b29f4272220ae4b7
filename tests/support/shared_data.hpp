#pragma once
// One rule for tests that read ../shared (SP_SHARED_DIR): a test may skip only when the whole shared
// folder is absent AND the environment variable CI is unset (a developer machine without the data).
// On CI, or when the folder exists, a missing file is a test failure naming the file.
//
//   #include "../support/shared_data.hpp"                  // from tests/<module>/*.cpp
//   SP_REQUIRE_SHARED(kSeq, kModels / "yolox_nano.onnx");  // in a TEST body or a fixture's SetUp()
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <initializer_list>
#include <string>

namespace sp::test {

// The environment variable CI is set (to anything, even empty): CI always has ../shared.
inline bool on_ci() { return std::getenv("CI") != nullptr; }

inline std::filesystem::path shared_dir() { return SP_SHARED_DIR; }

struct SharedCheck {
  enum class Verdict { kPresent, kSkip, kFail } verdict = Verdict::kPresent;
  std::string message;
};

// What to do about the paths a test needs; `whole_folder_present` and `ci` are parameters so the
// rule itself can be tested without changing the environment.
inline SharedCheck check_shared(std::initializer_list<std::filesystem::path> paths, bool whole_folder_present,
                                bool ci) {
  std::string missing;
  for (const auto& p : paths) {
    if (!std::filesystem::exists(p)) missing += (missing.empty() ? "" : ", ") + p.string();
  }
  if (missing.empty()) return {};
  if (!whole_folder_present && !ci) {
    return {SharedCheck::Verdict::kSkip,
            "no shared data folder " + shared_dir().string() + " (CI unset): skipped"};
  }
  return {SharedCheck::Verdict::kFail,
          "shared data missing: " + missing +
              (whole_folder_present ? std::string()
                                    : " (the whole folder " + shared_dir().string() + " is absent)") +
              (ci ? " [CI is set: missing data is a failure]" : "")};
}

inline SharedCheck check_shared(std::initializer_list<std::filesystem::path> paths) {
  return check_shared(paths, std::filesystem::is_directory(shared_dir()), on_ci());
}

}  // namespace sp::test

// Skips or fails (see above) and returns from the current void function when a path is missing.
#define SP_REQUIRE_SHARED(...)                                                                \
  do {                                                                                        \
    const ::sp::test::SharedCheck sp_shared_check_ = ::sp::test::check_shared({__VA_ARGS__}); \
    if (sp_shared_check_.verdict == ::sp::test::SharedCheck::Verdict::kSkip)                  \
      GTEST_SKIP() << sp_shared_check_.message;                                               \
    if (sp_shared_check_.verdict == ::sp::test::SharedCheck::Verdict::kFail)                  \
      FAIL() << sp_shared_check_.message;                                                     \
  } while (false)
