#!/usr/bin/env bash
# Sanitizer builds of the unit tests and of a short end-to-end run (docs/robustness.md).
#   scripts/sanitize.sh [address|thread|all]      (default all)
# address: ASan + UBSan (build-asan/), every unit test, then the e2e runs below.
# thread:  TSan (build-tsan/), the tests that start threads (queues, async detector, prefetching
#          reader, loop closer, the threaded pipeline), then the e2e runs below.
# E2E runs (both builds): `stillpoint run` threaded (not --deterministic, so tracking, local
# mapping, loop closing, the detector and the frame reader really run concurrently) on 60 frames
# of a dynsynth cut with YOLO + flow culling, then the same run stopped by SIGINT mid-way.
# Any sanitizer report fails the script (halt_on_error, and the logs are searched for reports).
# Environment:
#   SP_SAN_CXX      compiler (default clang++; g++ works too)
#   SP_JOBS         build jobs (default 2)          SP_NICE   niceness (default 10)
#   SP_SAN_MODULES  modules built (default: all but place and report, see below)
#   SP_SAN_DATA     sequence for the e2e runs (default ../shared/data/dynsynth/office_a_walking_xyz_150)
#   SP_TSAN_TESTS   ctest -R regex for the TSan build
# The place module (ParC_NetVLAD) links libtorch, which is not instrumented and whose training
# tests would run for tens of minutes under a sanitizer; report needs npm + Chromium at build time.
# Neither is on the threaded SLAM path (the netvlad loop detector is off by default).
# Both builds are configured -DSTILLPOINT_WITH_TORCH=OFF (they never build place), so CI's ASan
# build is also the build without libtorch (docs/library.md): the modules, the CLI and its API layer
# built and tested without it, and its ctest must pass the no-torch checks (cli_version says
# "without libtorch", cli_refuses_netvlad_without_torch), which the script checks ran.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
MODE="${1:-all}"
CXX_BIN="${SP_SAN_CXX:-clang++}"
JOBS="${SP_JOBS:-2}"
NICE="${SP_NICE:-10}"
MODULES="${SP_SAN_MODULES:-common;geometry;io;eval;features;dynamic;map;optimize;tracking;mapping;loop;pipeline}"
DATA="${SP_SAN_DATA:-$ROOT/../shared/data/dynsynth/office_a_walking_xyz_150}"
MODEL="$ROOT/../shared/models/yolox_nano.onnx"
TSAN_TESTS="${SP_TSAN_TESTS:-BoundedQueue|AsyncDetector|TumSequence|LoopCloser|EndToEnd|MapReuse}"
TSAN_TARGETS=(test_common test_dynamic test_io test_loop test_e2e stillpoint)

case "$MODE" in
  address | thread) MODES=("$MODE") ;;
  all) MODES=(address thread) ;;
  *) echo "usage: $0 [address|thread|all]" >&2; exit 2 ;;
esac
command -v "$CXX_BIN" >/dev/null || { echo "$CXX_BIN not found (scripts/setup.sh installs clang)" >&2; exit 2; }

# Reports go to stderr; halt_on_error turns the first one into a non-zero exit.
SAN_EXIT=86  # distinct from the CLI's own exit codes
export ASAN_OPTIONS="exitcode=$SAN_EXIT:halt_on_error=1:detect_leaks=1:detect_stack_use_after_return=1:strict_init_order=1:check_initialization_order=1"
export UBSAN_OPTIONS="exitcode=$SAN_EXIT:halt_on_error=1:print_stacktrace=1"
export TSAN_OPTIONS="exitcode=$SAN_EXIT:halt_on_error=1:second_deadlock_stack=1:history_size=4:suppressions=$ROOT/scripts/tsan.supp"
# The OpenNI2 tests that initialise the real library: its driver plugins (libDummyDevice, libPS1080,
# ...) leak a few kB per load and are dlclose'd before LeakSanitizer looks, so the leak stack ends
# in "<unknown module>" and cannot be suppressed by name. They run without leak detection (ASan's
# memory checks stay on).
NO_LEAK_TESTS='OpenNI2Source\.(NoDeviceGivesAClearError|MissingRecordingNamesTheUri)'
# Left out of the ASan run for time only: the 7-Scenes map-merge fault test takes ~440 s under ASan
# (33 s in Release); the merge code runs under ASan in Atlas.* and MapMerge.* and in the unseen-place
# fault test, which stay in.
ASAN_SKIP_TESTS='Faults\.KidnappedCameraWalkingBackIntoTheOldMapIsMerged'
REPORT_RE='ERROR: AddressSanitizer|ERROR: LeakSanitizer|WARNING: ThreadSanitizer|ThreadSanitizer: |runtime error:|SUMMARY: [A-Za-z]*Sanitizer'

status=0
fail() {
  echo "sanitize: FAILED: $*" >&2
  status=1
}

# Searches a log for sanitizer reports (catches reports from a process whose exit status is lost).
check_log() {
  if grep -Eq "$REPORT_RE" "$1"; then
    fail "sanitizer report in $1:"
    grep -E -m 5 -A 12 "$REPORT_RE" "$1" >&2 || true
  fi
}

# A threaded 60-frame run with YOLO + flow culling, then one stopped by SIGINT mid-way.
e2e_runs() {
  local build="$1" kind="$2"
  local app="$build/apps/stillpoint/stillpoint" out="$build/e2e"
  if [ ! -d "$DATA" ]; then
    echo "sanitize: $DATA missing, e2e runs skipped" >&2
    return
  fi
  local dyn=(--dynamic flow)
  [ -f "$MODEL" ] && dyn=(--dynamic detector+flow --detector-model "$MODEL")
  rm -rf "$out" && mkdir -p "$out"
  local t0=$SECONDS
  if ! nice -n "$NICE" "$app" run --dataset "$DATA" --max-frames 60 --no-progress "${dyn[@]}" \
    --out "$out/full" >"$out/full.log" 2>&1; then
    fail "$kind e2e run (see $out/full.log)"
  fi
  check_log "$out/full.log"
  grep -q '"completed": true' "$out/full/stats.json" 2>/dev/null || fail "$kind e2e run did not complete"
  echo "sanitize: $kind e2e run: $((SECONDS - t0)) s"

  # SIGINT mid-way: after half the time the 60-frame run took (about frame 30 of 150), when
  # tracking, local mapping, loop closing and the detector are all busy.
  local after="${SP_SIGINT_AFTER_S:-$(((SECONDS - t0) / 2 + 1))}"
  t0=$SECONDS
  nice -n "$NICE" "$app" run --dataset "$DATA" --no-progress "${dyn[@]}" --out "$out/sigint" \
    >"$out/sigint.log" 2>&1 &
  local pid=$!
  sleep "$after"
  kill -INT "$pid" 2>/dev/null || true
  local rc=0
  wait "$pid" || rc=$?
  # An interrupted run exits 1 (not completed); a sanitizer exits with SAN_EXIT below.
  if [ "$rc" -ne 0 ] && [ "$rc" -ne 1 ]; then
    fail "$kind SIGINT run exited $rc (see $out/sigint.log)"
  fi
  grep -q 'stop requested' "$out/sigint.log" || echo "sanitize: note: the SIGINT run had finished before the signal" >&2
  check_log "$out/sigint.log"
  [ -f "$out/sigint/stats.json" ] || fail "$kind SIGINT run wrote no stats.json"
  echo "sanitize: $kind SIGINT run (rc $rc): $((SECONDS - t0)) s"
}

for kind in "${MODES[@]}"; do
  t_start=$SECONDS
  if [ "$kind" = address ]; then
    build="$ROOT/build-asan"
    targets=()  # all: every unit test of the modules above and the CLI
    tests=(-E "$NO_LEAK_TESTS|$ASAN_SKIP_TESTS")
  else
    build="$ROOT/build-tsan"
    targets=("${TSAN_TARGETS[@]}")
    tests=(-R "$TSAN_TESTS")
  fi
  # -O1: sanitizer reports stay readable and the build stays quick; -g1: line tables for the
  # stack traces. NDEBUG as in Release, so the code under test is the shipped code.
  cmake -S "$ROOT" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DCMAKE_CXX_COMPILER="$CXX_BIN" -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1 -DNDEBUG" \
    -DSP_SANITIZE="$kind" -DSP_ONLY_MODULES="$MODULES" -DSTILLPOINT_WITH_TORCH=OFF >/dev/null
  if [ ${#targets[@]} -gt 0 ]; then
    nice -n "$NICE" cmake --build "$build" -j "$JOBS" --target "${targets[@]}"
  else
    nice -n "$NICE" cmake --build "$build" -j "$JOBS"
  fi
  t_built=$SECONDS
  log="$build/ctest.log"
  if ! (cd "$build" && nice -n "$NICE" ctest -j "$JOBS" --output-on-failure "${tests[@]}" >"$log" 2>&1); then
    fail "$kind unit tests (see $log)"
    grep -E '^\s*[0-9]+ - |tests passed|Failed' "$log" | tail -20 >&2 || true
  fi
  check_log "$log"
  grep -E 'tests passed' "$log" || true
  if [ "$kind" = address ]; then
    if ! (cd "$build" && ASAN_OPTIONS="$ASAN_OPTIONS:detect_leaks=0" ctest --output-on-failure \
      -R "$NO_LEAK_TESTS" >"$build/ctest_noleak.log" 2>&1); then
      fail "$kind OpenNI2 tests (see $build/ctest_noleak.log)"
    fi
    check_log "$build/ctest_noleak.log"
    # The no-torch build's own checks (tests/install/CMakeLists.txt) ran and passed.
    for t in cli_version cli_refuses_netvlad_without_torch; do
      grep -Eq ": $t \.+ +Passed" "$log" || fail "$kind: the no-torch check $t did not pass (see $log)"
    done
  fi
  t_tested=$SECONDS
  e2e_runs "$build" "$kind"
  echo "sanitize: $kind: build $((t_built - t_start)) s, tests $((t_tested - t_built)) s, e2e $((SECONDS - t_tested)) s"
done
[ "$status" -eq 0 ] && echo "sanitize: no sanitizer report"
exit $status
