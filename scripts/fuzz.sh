#!/usr/bin/env bash
# Builds the libFuzzer targets in fuzz/ with clang (ASan + UBSan) and runs each for SECONDS (default 10).
#   scripts/fuzz.sh [seconds] [target ...]
#   scripts/fuzz.sh --runs N [target ...]   # on demand: N executions per target (e.g. 1000000)
# Environment: BUILD_DIR (default build-fuzz), JOBS (default 1), NICE (default 19), FUZZ_ARGS (extra
# libFuzzer flags, e.g. "-fork=1 -ignore_crashes=1" to go on after a known crash).
# Seeds come from fuzz/corpus/<target>/ (committed, small); what the fuzzer finds goes to
# $BUILD_DIR/corpus/<target>/ and crashes to $BUILD_DIR/crashes/<target>/ (reproduce with
# `$BUILD_DIR/<target> <crash-file>`). Exit status 1 when any target crashed.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
LIMIT=()
if [ "${1:-}" = "--runs" ]; then
  LIMIT=(-runs="${2:?--runs needs a count}")
  shift 2
else
  LIMIT=(-max_total_time="${1:-10}")
  shift || true
fi
BUILD_DIR="${BUILD_DIR:-$ROOT/build-fuzz}"
JOBS="${JOBS:-1}"
NICE="${NICE:-19}"
TARGETS=("$@")
if [ ${#TARGETS[@]} -eq 0 ]; then
  TARGETS=(fuzz_tum_text fuzz_trajectory fuzz_config fuzz_vocabulary fuzz_boxes fuzz_map_file fuzz_model_config)
fi

command -v clang++ >/dev/null || { echo "clang++ not found: apt-get install clang libclang-rt-14-dev" >&2; exit 2; }
GEN=()
command -v ninja >/dev/null && GEN=(-G Ninja)
CC=clang CXX=clang++ cmake -S "$ROOT/fuzz" -B "$BUILD_DIR" "${GEN[@]}" >/dev/null
nice -n "$NICE" cmake --build "$BUILD_DIR" -j "$JOBS" --target "${TARGETS[@]}"

status=0
printf '%-18s %12s %10s %8s %8s %s\n' target executions exec/s seconds crashes result
for t in "${TARGETS[@]}"; do
  work="$BUILD_DIR/corpus/$t"
  crashes="$BUILD_DIR/crashes/$t"
  mkdir -p "$work" "$crashes"
  log="$BUILD_DIR/$t.log"
  stamp="$BUILD_DIR/$t.start"
  touch "$stamp"
  set +e
  # -rss_limit_mb / -malloc_limit_mb: a parser that allocates what a header claims is a finding.
  nice -n "$NICE" "$BUILD_DIR/$t" "$work" "$ROOT/fuzz/corpus/$t" "${LIMIT[@]}" \
    -print_final_stats=1 -rss_limit_mb=2048 -malloc_limit_mb=1024 -timeout=10 \
    -artifact_prefix="$crashes/" ${FUZZ_ARGS:-} >"$log" 2>&1
  rc=$?
  set -e
  execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' || true)
  # Fork mode prints "#N ... exec/s" progress lines instead of final stats: take the last count.
  [ -n "$execs" ] || execs=$(grep -o '^#[0-9]*' "$log" | tail -1 | tr -d '#' || true)
  speed=$(grep -o 'stat::average_exec_per_sec: *[0-9]*' "$log" | grep -o '[0-9]*$' || true)
  [ -n "$speed" ] || speed=$(grep -o 'exec/s: [0-9]*' "$log" | tail -1 | grep -o '[0-9]*$' || true)
  found=$(find "$crashes" -type f -newer "$stamp" | wc -l)  # findings of this run only
  if [ "$rc" -ne 0 ] || [ "$found" -ne 0 ]; then
    result="FAILED (rc $rc, see $log)"
    status=1
  else
    result=ok
  fi
  printf '%-18s %12s %10s %8s %8s %s\n' "$t" "$execs" "$speed" "$(($(date +%s) - $(stat -c %Y "$stamp")))" "$found" "$result"
done
exit $status
