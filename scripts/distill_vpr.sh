#!/usr/bin/env bash
# The Fig. 11-style ParC_NetVLAD ablation with the distilled initialisation (docs/place_recognition.md,
# "Distilled initialisation"): for each variant (plain ConvNeXt, +ParC, +ParC+CBAM) and each seed,
# `vpr distill` from the shipped YOLOX-nano teacher on the training rooms, then Recall@1/5/10/20 on
# the held-back rooms (901-903) and on the real Corridor set; ORB BoW with a vocabulary from the same
# rooms. Prints the table (mean ± std over the seeds) and writes WORK/results/summary.json.
# Run from the repository root after building `stillpoint`:
#   scripts/distill_vpr.sh [BUILD_DIR] [WORK_DIR]
# Environment: SEEDS ("1 2 3"), STEPS (1200), LR (3e-3), WIDTH (1: the small variant's widths),
# JOBS (runs at once, 2), ROOMS (40), TOP (teacher layer for the NetVLAD input, dark4), VARIANTS.
set -euo pipefail
BUILD=${1:-build}
WORK=${2:-/tmp/vpr_distill}
SP=$(realpath "${BUILD}/apps/stillpoint/stillpoint")
ROOT=$(cd "$(dirname "$0")/.." && pwd)
D=$ROOT/../shared/tools/dynsynth/dynsynth.py
CORRIDOR=$ROOT/../shared/data/vpr/corridor
TEACHER=$ROOT/models/yolox_nano/yolox_nano.onnx
PY=/usr/bin/python3
SEEDS=${SEEDS:-1 2 3}
STEPS=${STEPS:-1200}
LR=${LR:-3e-3}
WIDTH=${WIDTH:-1}
JOBS=${JOBS:-2}
TOP=${TOP:-onnx_node!Mul_161}
VARIANTS=${VARIANTS:-convnext:off:off parc:on:off parc_cbam:on:on}
export STILLPOINT_DATA_DIR=${STILLPOINT_DATA_DIR:-$ROOT/${BUILD}/share/stillpoint}
[[ -x $SP ]] || { echo "build stillpoint first: $SP" >&2; exit 2; }

mkdir -p "$WORK/eval" "$WORK/models" "$WORK/results" "$WORK/logs"
# 1. Data: the training and validation rooms, and the held-back evaluation rooms.
"$ROOT/scripts/render_vpr_trainset.sh" "$WORK/set" "${ROOMS:-40}"
for n in 901 902 903; do
  [[ -f $WORK/eval/random_$n/poses.txt ]] || nice -n 10 $PY "$D" places --scene random --scene-seed "$n" \
      --count 400 --seed 1 --width 320 --height 240 --out "$WORK/eval/random_$n" --people
done

# 2. One distillation per variant and seed, JOBS at a time (one libtorch thread each).
one() {  # name:parc:cbam seed
  IFS=: read -r name parc cbam <<< "$1"
  local out=$WORK/models/${name}_s$2.pt
  [[ -f $out ]] && return 0
  nice -n 10 "$SP" vpr distill --data "$WORK/set/train" --val "$WORK/set/val" --out "$out" \
      --teacher "$TEACHER" --teacher-top "$TOP" --parc "$parc" --cbam "$cbam" --width-mult "$WIDTH" \
      --steps "$STEPS" --lr "$LR" --seed "$2" --threads 1 --no-progress > "$WORK/logs/${name}_s$2.log" 2>&1
}
export -f one
export SP WORK TEACHER TOP WIDTH STEPS LR
for v in $VARIANTS; do for s in $SEEDS; do echo "$v $s"; done; done | xargs -P "$JOBS" -L 1 bash -c 'one $0 $1'

# 3. Evaluation: every model and the BoW baseline on the held-back rooms and Corridor.
[[ -f $WORK/models/bow_orb.voc ]] || nice -n 10 "$SP" vpr bow-train --data "$WORK/set/train" --out "$WORK/models/bow_orb.voc"
for f in "$WORK"/models/*.pt "$WORK/models/bow_orb.voc"; do
  m=$(basename "${f%.*}")
  if [[ $f == *.voc ]]; then arg=(--bow "$f"); else arg=(--model "$f"); fi
  for set in places corridor; do
    case $set in places) ds=$WORK/eval;; corridor) ds=$CORRIDOR;; esac
    out=$WORK/results/${m}_$set.json
    [[ -f $out ]] || nice -n 10 "$SP" vpr eval "${arg[@]}" --dataset "$ds" --json "$out" --threads 1 --no-progress
  done
done

# 4. Mean ± std over the seeds (sample std), one table per set.
$PY - "$WORK/results" $VARIANTS <<'PYEOF'
import json, os, re, statistics, sys
res, variants = sys.argv[1], [v.split(":")[0] for v in sys.argv[2:]]
labels = {"convnext": "ConvNeXt+NetVLAD", "parc": "ParC-ConvNeXt+NetVLAD", "parc_cbam": "ParC-ConvNeXt+CBAM+NetVLAD"}
summary = {}
for key, title in [("places", "dynsynth held-back rooms 901-903"), ("corridor", "Corridor")]:
    bow = json.load(open(os.path.join(res, f"bow_orb_{key}.json")))
    print(f"\n**{title}** ({bow['queries']} queries)\n")
    print("| method | seeds | R@1 | R@5 | R@10 | R@20 | ms/image |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    print(f"| BoW (ORB) | - | {bow['recall@1']:.3f} | {bow['recall@5']:.3f} | {bow['recall@10']:.3f} | "
          f"{bow['recall@20']:.3f} | {bow['ms_per_image']:.1f} |")
    summary.setdefault(key, {})["bow_orb"] = bow
    for v in variants:
        runs = [json.load(open(os.path.join(res, f))) for f in sorted(os.listdir(res))
                if re.fullmatch(rf"{v}_s\d+_{key}\.json", f)]
        if not runs:
            continue
        cell = lambda k: (f"{statistics.mean(r[k] for r in runs):.3f} ± "
                          f"{(statistics.stdev(r[k] for r in runs) if len(runs) > 1 else 0):.3f}")
        print(f"| {labels.get(v, v)} | {len(runs)} | {cell('recall@1')} | {cell('recall@5')} | "
              f"{cell('recall@10')} | {cell('recall@20')} | {statistics.mean(r['ms_per_image'] for r in runs):.1f} |")
        summary[key][v] = {k: [r[k] for r in runs] for k in ("recall@1", "recall@5", "recall@10", "recall@20")}
json.dump(summary, open(os.path.join(res, "summary.json"), "w"), indent=1)
PYEOF
