// Local bundle adjustment at the size profiling shows in the mapper: 20 free + 20 fixed keyframes,
// 2500 points, ~16000 observations (90 % stereo), 5 % gross outliers, default BAConfig (5 + 10
// iterations); and a problem at the native solver's free-keyframe limit (60 free + 10 fixed,
// 6000 points). One benchmark per solver and size (arguments: free keyframes, fixed keyframes,
// points); counters report the costs, the iterations and the outliers, so the two solvers can be
// checked to agree.
//
//   build/bench/bench_bundle_adjustment --benchmark_repetitions=9 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>

#include <string>

#include "stillpoint/optimize/bundle_adjustment.hpp"
#include "synthetic.hpp"

namespace {

sp::opt::test::BAScene make_scene(const benchmark::State& state) {
  sp::opt::test::BASceneSpec spec;  // 90 % stereo, span 3 (~6.4 observations per point)
  spec.free_keyframes = static_cast<int>(state.range(0));
  spec.fixed_keyframes = static_cast<int>(state.range(1));
  spec.points = static_cast<int>(state.range(2));
  spec.outlier_ratio = 0.05;
  spec.seed = 21;
  return sp::opt::test::make_ba_scene(spec);
}

void BM_LocalBundleAdjustment(benchmark::State& state, const std::string& solver) {
  const sp::opt::test::BAScene scene = make_scene(state);
  sp::opt::BAConfig config;
  config.solver = solver;
  sp::opt::BAResult result;
  for (auto _ : state) {
    state.PauseTiming();
    sp::opt::BAProblem problem = scene.problem;
    state.ResumeTiming();
    result = sp::opt::run_bundle_adjustment(problem, sp::opt::test::test_camera(), config);
    benchmark::DoNotOptimize(problem.keyframes.data());
  }
  int outliers = 0;
  for (const bool o : result.outlier) outliers += o ? 1 : 0;
  state.counters["initial_cost"] = result.initial_cost;
  state.counters["final_cost"] = result.final_cost;
  state.counters["iterations"] = result.iterations;
  state.counters["outliers"] = outliers;
  state.counters["observations"] = static_cast<double>(scene.problem.observations.size());
}

BENCHMARK_CAPTURE(BM_LocalBundleAdjustment, native, std::string("native"))
    ->Args({20, 20, 2500})
    ->Args({sp::opt::kNativeBAMaxFreeKeyframes, 10, 6000})
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_LocalBundleAdjustment, ceres, std::string("ceres"))
    ->Args({20, 20, 2500})
    ->Args({sp::opt::kNativeBAMaxFreeKeyframes, 10, 6000})
    ->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
