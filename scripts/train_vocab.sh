#!/usr/bin/env bash
# Reproduces the shipped vocabulary data/vocab/stillpoint_orb.spv: renders place images of random
# dynsynth rooms outside the room suite (seeds 901-910; the suite's tune rooms are 101-108 and its
# held-back rooms 201-204, scripts/room_suite.sh; never office_a, 7-Scenes or VPR data), so no image of
# any benchmark room is in the training set, then trains a k=10, L=5 ORB vocabulary with a fixed seed.
# Usage: scripts/train_vocab.sh [BUILD_DIR]   (BUILD_DIR holds apps/stillpoint/stillpoint; default build)
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
BUILD="${1:-$ROOT/build}"
D="$ROOT/../shared/tools/dynsynth/dynsynth.py"
TRAIN="${VOCAB_TRAIN_DIR:-/tmp/vocab_train_outside_suite}"
OUT="${VOCAB_OUT:-$ROOT/data/vocab/stillpoint_orb.spv}"

# 10 rooms x 150 views at 640x480; every other room with standing people (they are part of the
# scenes the system sees, so their texture words should exist in the vocabulary).
SEEDS=(901 902 903 904 905 906 907 908 909 910)
dirs=()
for s in "${SEEDS[@]}"; do
  people=()
  if (( s % 2 == 0 )); then people=(--people); fi
  dir="$TRAIN/random_$s"
  if [[ ! -f "$dir/info.json" ]]; then
    nice -n 10 /usr/bin/python3 "$D" places --scene random --scene-seed "$s" --count 150 --seed 1 \
      --width 640 --height 480 "${people[@]}" --out "$dir"
  fi
  dirs+=("$dir")
done

mkdir -p "$(dirname "$OUT")"
nice -n 10 "$BUILD/apps/stillpoint/stillpoint" vocab train --images "${dirs[@]}" --out "$OUT" \
  --k 10 --levels 5 --features 1000 --max-images 1500 --seed 1
"$BUILD/apps/stillpoint/stillpoint" vocab info "$OUT"
