#!/usr/bin/env bash
# The room-suite benchmark of issue 13: every sequence of the random-room suite (scripts/room_suite.sh)
# with the shipped settings ("default": YOLOX-nano + flow culling), culling off, or oracle boxes, and the two peers when they are built
# (../shared/tools/peer_orbslam2, ../shared/tools/peer_ngdslam), threaded, 3 repeats each; one table
# per sequence (medians, ATE spread) and a summary per variant for the tune and held-back groups.
# Usage: scripts/bench_rooms.sh [SUITE_DIR] [OUT_DIR] [extra bench args...]
#   e.g. scripts/bench_rooms.sh ~/room_suite/heldout bench_rooms_heldout --repeats 3
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
B="${SP_BUILD_DIR:-$root/build}/apps/stillpoint/stillpoint"
SUITE="${1:-${ROOM_SUITE:-$HOME/room_suite}}"
OUT="${2:-$root/bench_rooms}"
shift $(($# > 2 ? 2 : $#))
M="$root/../shared/models/yolox_nano.onnx"
peers=()
[ -x "${ORBSLAM2_DIR:-${XDG_CACHE_HOME:-$HOME/.cache}/stillpoint-peers/orbslam2}/Examples/RGB-D/rgbd_tum" ] && peers+=(orbslam2)
[ -x "${NGD_DIR:-${XDG_CACHE_HOME:-$HOME/.cache}/stillpoint-peers/ngdslam}/Examples/RGB-D/rgbd_tum" ] && peers+=(ngdslam)
peer_args=()
((${#peers[@]})) && peer_args=(--peers "$(IFS=,; echo "${peers[*]}")")
"$B" bench --suite "$SUITE" --detector-model "$M" --out "$OUT" --repeats 3 \
  --variant "off=--dynamic off" --variant "default=" \
  --variant "oracle=--dynamic oracle" \
  "${peer_args[@]}" "$@"
