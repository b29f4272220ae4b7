#pragma once
// Scratch files for the io tests.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

namespace sp::io::test {

// A fresh folder under SP_TEST_TMP_DIR named after the running test.
inline std::filesystem::path scratch_dir() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const std::filesystem::path dir = std::filesystem::path(SP_TEST_TMP_DIR) / "io" /
                                    (std::string(info->test_suite_name()) + "_" + info->name());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

inline std::filesystem::path write_text(const std::filesystem::path& file, const std::string& text) {
  std::ofstream(file, std::ios::binary) << text;
  return file;
}

}  // namespace sp::io::test
