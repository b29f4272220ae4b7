#!/usr/bin/env bash
# The main job on the built-in default: install, build, run SLAM on the bundled sequence, print ATE.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
"$root/scripts/setup.sh"
"$root/scripts/build.sh"
"${SP_BUILD_DIR:-$root/build}/apps/stillpoint/stillpoint" run --out "${1:-$root/demo_out}"
