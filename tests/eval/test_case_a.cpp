// The figures of the TUM benchmark's own scripts on ../shared/data/eval/case_a must be reproduced.
#include <gtest/gtest.h>

#include <fstream>

#include "../support/shared_data.hpp"
#include "stillpoint/eval/evaluate.hpp"
#include "stillpoint/io/trajectory_io.hpp"

namespace sp::eval {
namespace {

const std::filesystem::path kCase = SP_SHARED_DIR "/data/eval/case_a";

void expect_matches(const EvalResult& r, const std::filesystem::path& expected_file) {
  std::ifstream in(expected_file);
  ASSERT_TRUE(in) << expected_file;
  const auto expected = nlohmann::json::parse(in);
  const auto got = to_json(r);
  EXPECT_EQ(got.at("pairs"), expected.at("pairs"));
  EXPECT_EQ(got.at("rpe_pairs"), expected.at("rpe_pairs"));
  for (const char* block : {"ate", "rpe_trans", "rpe_rot_deg"}) {
    for (const char* f : {"rmse", "mean", "median", "std", "min", "max"}) {
      EXPECT_NEAR(got.at(block).at(f).get<double>(), expected.at(block).at(f).get<double>(), 1e-6)
          << block << "." << f;
    }
  }
}

TEST(CaseA, ReproducesTumScriptsWithDeltaOneSecond) {
  SP_REQUIRE_SHARED(kCase / "gt.txt", kCase / "est.txt");
  const auto gt = io::read_tum_trajectory(kCase / "gt.txt");
  const auto est = io::read_tum_trajectory(kCase / "est.txt");
  expect_matches(evaluate(gt, est, {}), kCase / "expected.json");
}

TEST(CaseA, ReproducesTumScriptsWithDeltaThirtyFrames) {
  SP_REQUIRE_SHARED(kCase / "gt.txt", kCase / "est.txt");
  const auto gt = io::read_tum_trajectory(kCase / "gt.txt");
  const auto est = io::read_tum_trajectory(kCase / "est.txt");
  EvalOptions o;
  o.delta = 30;
  o.delta_unit = DeltaUnit::Frames;
  expect_matches(evaluate(gt, est, o), kCase / "expected_f30.json");
}

}  // namespace
}  // namespace sp::eval
