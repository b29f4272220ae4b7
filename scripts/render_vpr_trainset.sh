#!/usr/bin/env bash
# Renders the dynsynth `places` rooms for training ParC_NetVLAD at scale (docs/place_recognition.md,
# "Training that converges"):
#   scripts/render_vpr_trainset.sh [OUT_DIR] [N_ROOMS] [--jobs K] [--count VIEWS]
# OUT_DIR/train/random_S for the first N_ROOMS usable scene seeds S from 1001 up (default 40 rooms, 400
# views each, 320×240; odd seeds without people, even seeds with 0–2 people per view) and
# OUT_DIR/val/random_S for the first 2 usable seeds from 951 up (with people), for `vpr train --val`.
# "Usable": dynsynth's random-room generator rejects some seeds ("no room for the workstation", e.g.
# 952, 1019, 1025); those are skipped, so 40 rooms take seeds 1001–1042. The ranges (train 1001–1899,
# val 951–999) never overlap the held-back evaluation rooms 901–903 nor the SLAM suites' rooms 101–112
# and 201–212. Rooms already rendered (poses.txt present) are skipped, so an interrupted run resumes;
# each room renders into a temporary folder first.
# dynsynth has no lighting option: lighting and exposure variety comes from the training loader's
# augmentation (--augment on), not from the renders.
set -euo pipefail
OUT=/tmp/vpr_trainset
N=40
JOBS=1
COUNT=400
pos=()
usage_error() {
  echo "render_vpr_trainset.sh: $1" >&2
  echo "usage: scripts/render_vpr_trainset.sh [OUT_DIR] [N_ROOMS] [--jobs K] [--count VIEWS]" >&2
  exit 2
}
while (($#)); do
  case $1 in
    --jobs|--count)
      (($# >= 2)) || usage_error "$1 needs a value"
      if [[ $1 == --jobs ]]; then JOBS=$2; else COUNT=$2; fi
      shift 2 ;;
    -h|--help) sed -n '2,12p' "$0"; exit 0 ;;
    -?*) usage_error "unknown option $1" ;;
    *) pos+=("$1"); shift ;;
  esac
done
((${#pos[@]} <= 2)) || usage_error "too many arguments (${pos[*]:2}): at most OUT_DIR and N_ROOMS"
((${#pos[@]} > 0)) && OUT=${pos[0]}
((${#pos[@]} > 1)) && N=${pos[1]}
if ! [[ $N =~ ^[0-9]+$ ]] || ((N < 1 || N > 800)); then echo "N_ROOMS must be 1..800 (seeds 1001..1899)" >&2; exit 2; fi
if ! [[ $JOBS =~ ^[0-9]+$ ]] || ((JOBS < 1)); then echo "--jobs must be a positive integer" >&2; exit 2; fi
if ! [[ $COUNT =~ ^[0-9]+$ ]] || ((COUNT < 2)); then echo "--count must be an integer >= 2" >&2; exit 2; fi
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
D=${DYNSYNTH:-$ROOT/../shared/tools/dynsynth/dynsynth.py}
PY=/usr/bin/python3
[[ -f $D ]] || { echo "dynsynth not found at $D (set DYNSYNTH)" >&2; exit 2; }
# The first N seeds in [first, last] for which dynsynth can build a random room (cheap: no rendering).
usable_seeds() {  # first last n
  (cd "$(dirname "$D")" && $PY - "$@" <<'PYEOF'
import sys, scenes
first, last, n = map(int, sys.argv[1:])
out = []
for s in range(first, last + 1):
    try:
        scenes.build("random", s)
    except RuntimeError:
        continue
    out.append(s)
    if len(out) == n:
        break
if len(out) < n:
    sys.exit("only %d usable room seeds in %d-%d" % (len(out), first, last))
print(" ".join(map(str, out)))
PYEOF
  )
}
TRAIN_SEEDS=$(usable_seeds 1001 1899 "$N")  # training rooms
VAL_SEEDS=$(usable_seeds 951 999 2)           # validation rooms (with people), never trained on

render() {  # seed out_dir people(0|1)
  local seed=$1 dir=$2 people=()
  [[ $3 == 1 ]] && people=(--people)
  [[ -f $dir/poses.txt ]] && { echo "skip $dir (rendered)"; return 0; }
  rm -rf "$dir.tmp"
  nice -n 10 $PY "$D" places --scene random --scene-seed "$seed" --count "$COUNT" --seed 1 \
      --width 320 --height 240 --out "$dir.tmp" "${people[@]}" >"$dir.log" 2>&1 \
    || { echo "FAILED $dir (see $dir.log)" >&2; rm -rf "$dir.tmp"; return 1; }
  # A $dir without poses.txt (an empty or half-copied folder) is replaced, never rendered into: plain
  # `mv` would move the render inside it. -T: treat $dir as the target name, not a folder to move into.
  rm -rf "$dir"
  mv -T "$dir.tmp" "$dir"
  echo "rendered $dir"
}

mkdir -p "$OUT/train" "$OUT/val"
# One entry per room in three parallel arrays (OUT_DIR may contain spaces: no word splitting).
job_seed=() job_dir=() job_people=()
for s in $TRAIN_SEEDS; do
  job_seed+=("$s") job_dir+=("$OUT/train/random_$s") job_people+=($((s % 2 == 0 ? 1 : 0)))
done
for s in $VAL_SEEDS; do job_seed+=("$s") job_dir+=("$OUT/val/random_$s") job_people+=(1); done

# K renders at a time; the first failure is reported at the end (the others still finish).
fail=0
running=0
for i in "${!job_seed[@]}"; do
  render "${job_seed[i]}" "${job_dir[i]}" "${job_people[i]}" &
  running=$((running + 1))
  if ((running >= JOBS)); then
    wait -n || fail=1
    running=$((running - 1))
  fi
done
while ((running > 0)); do
  wait -n || fail=1
  running=$((running - 1))
done
((fail == 0)) || { echo "some rooms failed to render" >&2; exit 1; }
echo "train: $OUT/train ($N rooms, seeds $TRAIN_SEEDS), val: $OUT/val (seeds $VAL_SEEDS)"
