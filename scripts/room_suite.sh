#!/usr/bin/env bash
# Renders the room suite: random dynsynth rooms x camera/people motions, for tuning and for held-back
# evaluation. Tune on the "tune" seeds only; the "heldout" seeds are for reporting (never tune on them).
#
#   scripts/room_suite.sh [--set tune|heldout|all] [--frames N] [--out DIR] [--workers N] [--motions "m1 m2"]
#
# Layout: OUT/<set>/room<seed>_<motion>/ (TUM layout with masks/ and boxes.txt). Existing complete
# sequences are skipped, so the script can be re-run to finish an interrupted render.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
dynsynth="${DYNSYNTH_TOOL:-$root/../shared/tools/dynsynth/dynsynth.py}"
out="${ROOM_SUITE:-$HOME/room_suite}"
set_name="all"
frames=400
workers=1
motions="walking_static walking_xyz walking_rpy walking_halfsphere sitting_static"
# Fixed split: the held-back seeds never change, so "held-back" means the same rooms for everyone. Tune
# rooms 105-108 were added in session 15 (2026-12-03) to look for the held-back rooms' failures on rooms
# we may tune on; the held-back rooms were not touched. Held-back rooms 205-208 were added in session 24
# (2026-12-05): 201-204 had been reported on for twenty sessions (docs/results.md, "Session 24").
# Rooms 209-216 were added in session 26 (2026-12-05) as fresh judges for a setting first looked at on
# 205-208 (docs/results.md, "Session 26").
tune_seeds="101 102 103 104 105 106 107 108"
# Rooms 217-224 were added in session 27 (2026-12-05) to judge the MSAC camera-motion fit (docs/results.md,
# "Session 27"); rooms 225-232 in session 28 to judge the triangulation ratio ("Session 28"); rooms
# 233-236 in session 29 to measure the shipped defaults on rooms no setting had seen ("Session 29"); 237-240
# in session 30 to judge the new-point motion check ("Session 30"); 241-244 in session 31 to measure the
# shipped defaults against NGD-SLAM timed like for like, 245-248 in session 31 to judge waiting for the
# first detection ("Session 31"); 249-252 and 253-256 in session 32 to judge depthless_homography ("Session 32");
# 257-260 in session 33, rendered for a motion prior that failed before its judge, so used to measure the
# shipped defaults; 261-264 in session 33 to judge the prior where few points are matched ("Session 33");
# 265-268 in session 34 to judge coasting every culled box and to measure the shipped defaults ("Session 34");
# 269-272 rendered at the end of session 34, used in session 35 to measure the shipped defaults (its four
# candidates failed their screens, "Session 35"); 273-276 rendered in session 35, used in session 36 to judge
# the joint camera fit with the coverage fallback ("Session 36"); 277-280 rendered in session 36, used in
# session 37 to judge a bound on local BA's keyframe moves and to measure the shipped defaults ("Session 37");
# 281-308 in session 38, walking_halfsphere only (and room 296's other walking motions), searched for
# rooms where local BA carries a keyframe > 3 cm, to judge two local-BA guards ("Session 38").
# 318, 325, 345, 367, 390 in session 39, only their walking_xyz / _rpy / _halfsphere sequences that
# scripts/scout_rooms.py found crowded (people cover >= 0.2), to judge the weak-keyframe hold ("Session 39").
# Sessions 40-43 rendered only the crowded sequences of later seeds the same way, with --heldout-seeds N
# --motions M: 402, 405, 473, 485, 486, 530 (session 40), 678, 687, 707, 744, 761 (session 41), 806 and 880
# (session 42, scouted over seeds 801-893), 903 and 923 (session 43, seeds 894-960); docs/results.md names
# each sequence.
heldout_seeds="201 202 203 204 205 206 207 208 209 210 211 212 213 214 215 216 217 218 219 220 221 222 223 224 225 226 227 228 229 230 231 232 233 234 235 236 237 238 239 240 241 242 243 244 245 246 247 248 249 250 251 252 253 254 255 256 257 258 259 260 261 262 263 264 265 266 267 268 269 270 271 272 273 274 275 276 277 278 279 280 281 282 283 284 285 286 287 288 289 290 291 292 293 294 295 296 297 298 299 300 301 302 303 304 305 306 307 308 318 325 345 367 390"
while (($#)); do
  case "$1" in
    --set) set_name="$2"; shift 2 ;;
    --frames) frames="$2"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    --workers) workers="$2"; shift 2 ;;
    --motions) motions="$2"; shift 2 ;;
    --tune-seeds) tune_seeds="$2"; shift 2 ;;
    --heldout-seeds) heldout_seeds="$2"; shift 2 ;;
    -h|--help) sed -n 2,9p "$0"; exit 0 ;;
    *) echo "room_suite.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
case "$set_name" in
  tune) sets="tune" ;;
  heldout) sets="heldout" ;;
  all) sets="tune heldout" ;;
  *) echo "room_suite.sh: --set must be tune, heldout or all" >&2; exit 2 ;;
esac
mkdir -p "$out"
python=/usr/bin/python3  # Debian's, with python3-numpy and python3-opencv
"$python" -c 'import cv2, numpy' 2>/dev/null || {
  echo "room_suite.sh: needs Debian's python3-opencv and python3-numpy (scripts/setup.sh installs them)" >&2
  exit 1
}
for s in $sets; do
  seeds="$tune_seeds"
  [ "$s" = heldout ] && seeds="$heldout_seeds"
  for seed in $seeds; do
    for motion in $motions; do
      dir="$out/$s/room${seed}_${motion}"
      if [ -f "$dir/meta/info.json" ] && [ "$(grep -vc '^#' "$dir/rgb.txt" 2>/dev/null || echo 0)" -ge "$frames" ]; then
        echo "room_suite: $dir exists, skipped"
        continue
      fi
      echo "room_suite: rendering $dir ($frames frames)"
      rm -rf "$dir"
      "$python" "$dynsynth" render --scene random --scene-seed "$seed" --motion "$motion" --frames "$frames" \
        --seed "$seed" --rgb-format jpg --workers "$workers" --out "$dir" >"$out/.render_${s}_${seed}_${motion}.log" 2>&1 \
        || { echo "room_suite: render failed, see $out/.render_${s}_${seed}_${motion}.log" >&2; exit 1; }
    done
  done
done
echo "room_suite: done ($out)"
