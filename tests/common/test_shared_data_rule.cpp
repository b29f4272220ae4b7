// The rule of tests/support/shared_data.hpp: skip only when the whole shared folder is absent and CI
// is unset; otherwise a missing file fails the test.
#include <gtest/gtest.h>

#include <filesystem>

#include "../support/shared_data.hpp"

namespace sp::test {
namespace {

using Verdict = SharedCheck::Verdict;
const std::filesystem::path kHere = SP_SOURCE_DIR "/tests/support/shared_data.hpp";
const std::filesystem::path kMissing = SP_SOURCE_DIR "/tests/support/no_such_file.bin";

TEST(SharedDataRule, PresentFilesPassWhateverTheEnvironment) {
  for (bool folder : {false, true}) {
    for (bool ci : {false, true}) EXPECT_EQ(check_shared({kHere}, folder, ci).verdict, Verdict::kPresent);
  }
}

TEST(SharedDataRule, SkipsOnlyWithoutTheFolderAndWithoutCi) {
  EXPECT_EQ(check_shared({kHere, kMissing}, /*whole_folder_present=*/false, /*ci=*/false).verdict,
            Verdict::kSkip);
}

TEST(SharedDataRule, OnCiAMissingFileFailsEvenWithoutTheFolder) {
  const SharedCheck c = check_shared({kMissing}, /*whole_folder_present=*/false, /*ci=*/true);
  EXPECT_EQ(c.verdict, Verdict::kFail);
  EXPECT_NE(c.message.find(kMissing.string()), std::string::npos) << c.message;
}

TEST(SharedDataRule, WithTheFolderPresentAMissingFileFails) {
  for (bool ci : {false, true}) {
    const SharedCheck c = check_shared({kHere, kMissing}, /*whole_folder_present=*/true, ci);
    EXPECT_EQ(c.verdict, Verdict::kFail);
    EXPECT_NE(c.message.find("no_such_file.bin"), std::string::npos) << c.message;
    EXPECT_EQ(c.message.find("shared_data.hpp"), std::string::npos) << "only missing paths are named";
  }
}

}  // namespace
}  // namespace sp::test
