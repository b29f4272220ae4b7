#!/usr/bin/env bash
# Reproduces the ParC_NetVLAD ablation (docs/place_recognition.md): renders the dynsynth training and
# held-back evaluation rooms, trains the three variants identically, trains the BoW baseline and
# evaluates everything on the same splits. Run from the repository root after building `stillpoint`.
#   scripts/train_vpr.sh [BUILD_DIR] [WORK_DIR]
# The shipped model is the ParC+CBAM variant: models/parc_netvlad/parc_netvlad_small.pt.
set -euo pipefail
BUILD=${1:-build}
WORK=${2:-/tmp/vpr}
SP=${BUILD}/apps/stillpoint/stillpoint
D=../shared/tools/dynsynth/dynsynth.py
VPR=../shared/data/vpr
PY=/usr/bin/python3
THREADS=${THREADS:-1}
EPOCHS=${EPOCHS:-8}
QPE=${QPE:-96}
TRAIN_SEEDS="101 102 103 104"   # training rooms
EVAL_SEEDS="901 902 903"                                           # held back: never trained on
COMMON=(--epochs "$EPOCHS" --queries-per-epoch "$QPE" --lr 1e-3 --margin 0.1 --negatives 5 --seed 1
        --threads "$THREADS" --variant small --refresh-every 96 --negative-pool 200 --kmeans-images 100 --no-progress)

mkdir -p "$WORK/train" "$WORK/eval" "$WORK/models" "$WORK/results"
# 1. Data: 400 views per room at 320x240; every other training room and all eval rooms with people.
for n in $TRAIN_SEEDS; do
  people=""; if (( n % 2 == 0 )); then people="--people"; fi
  [[ -f $WORK/train/random_$n/poses.txt ]] || nice -n 10 $PY $D places --scene random --scene-seed "$n" \
      --count 400 --seed 1 --width 320 --height 240 --out "$WORK/train/random_$n" $people
done
for n in $EVAL_SEEDS; do
  [[ -f $WORK/eval/random_$n/poses.txt ]] || nice -n 10 $PY $D places --scene random --scene-seed "$n" \
      --count 400 --seed 1 --width 320 --height 240 --out "$WORK/eval/random_$n" --people
done

# 2. Three variants, trained identically (same data, epochs, seed).
train() {  # name parc cbam
  [[ -f $WORK/models/$1.pt ]] || nice -n 10 "$SP" vpr train --data "$WORK/train" --out "$WORK/models/$1.pt" \
      --parc "$2" --cbam "$3" "${COMMON[@]}"
}
train convnext_netvlad off off
train parc_netvlad on off
train parc_cbam_netvlad on on
[[ -f $WORK/models/bow_orb.voc ]] || nice -n 10 "$SP" vpr bow-train --data "$WORK/train" --out "$WORK/models/bow_orb.voc"

# 3. Evaluation on the held-back rooms and the two real sets.
for m in convnext_netvlad parc_netvlad parc_cbam_netvlad bow_orb; do
  if [[ $m == bow_orb ]]; then arg=(--bow "$WORK/models/bow_orb.voc"); else arg=(--model "$WORK/models/$m.pt"); fi
  for set in places nordland corridor; do
    case $set in places) ds=$WORK/eval;; *) ds=$VPR/$set;; esac
    out=$WORK/results/${m}_$set.json
    [[ -f $out ]] || nice -n 10 "$SP" vpr eval "${arg[@]}" --dataset "$ds" --json "$out" --threads "$THREADS" --no-progress
  done
done

# 4. The table for docs/place_recognition.md.
$PY - "$WORK/results" <<'PYEOF'
import json, sys, os
res = sys.argv[1]
rows = [("BoW (ORB)", "bow_orb"), ("ConvNeXt+NetVLAD", "convnext_netvlad"),
        ("ParC-ConvNeXt+NetVLAD", "parc_netvlad"), ("ParC-ConvNeXt+CBAM+NetVLAD", "parc_cbam_netvlad")]
sets = [("places", "dynsynth held-back rooms"), ("nordland", "Nordland winter→summer (±2)"),
        ("corridor", "Corridor")]
for key, title in sets:
    first = json.load(open(os.path.join(res, f"bow_orb_{key}.json")))
    print(f"\n**{title}** ({first['queries']} queries, {first['database']} database images)\n")
    print("| method | R@1 | R@5 | R@10 | R@20 | ms/image |")
    print("| --- | --- | --- | --- | --- | --- |")
    for label, name in rows:
        f = os.path.join(res, f"{name}_{key}.json")
        if not os.path.exists(f):
            continue
        j = json.load(open(f))
        print(f"| {label} | {j['recall@1']:.3f} | {j['recall@5']:.3f} | {j['recall@10']:.3f} | "
              f"{j['recall@20']:.3f} | {j['ms_per_image']:.1f} |")
PYEOF
