#!/usr/bin/env bash
# The test command: install dependencies, build, run the whole CTest suite.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
"$root/scripts/setup.sh"
"$root/scripts/build.sh"
cd "${SP_BUILD_DIR:-$root/build}"
ctest --output-on-failure -j "${SP_JOBS:-$(nproc)}" "$@"
