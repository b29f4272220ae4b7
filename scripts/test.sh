#!/usr/bin/env bash
# The test command: install dependencies, build, run the whole CTest suite, then the sanitizer and
# fuzzing stages (skipped with SP_QUICK_TEST=1).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
"$root/scripts/setup.sh"
"$root/scripts/build.sh"
(cd "${SP_BUILD_DIR:-$root/build}" && ctest --output-on-failure -j "${SP_JOBS:-$(nproc)}" "$@")
# Robustness stages (docs/robustness.md): ASan+UBSan and TSan builds of the unit tests and a short
# threaded e2e run, then every libFuzzer target for 30 s from its seeds. SP_QUICK_TEST=1 skips them
# (developers: the plain ctest above takes about 10 minutes, these stages about 40 more on 2 cores).
if [ "${SP_QUICK_TEST:-0}" != 1 ]; then
  "$root/scripts/sanitize.sh" all
  JOBS="${SP_JOBS:-$(nproc)}" "$root/scripts/fuzz.sh" "${SP_FUZZ_SECONDS:-30}"
fi
