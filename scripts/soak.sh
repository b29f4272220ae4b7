#!/usr/bin/env bash
# Soak run: one sequence played PASSES times back to back (default 3) by the threaded pipeline, with
# the current RSS sampled every 100 frames (stats.json rss_timeline_mib). Fails when the run does not
# complete or when memory is not flat: RSS at the end of the last pass more than SOAK_MAX_GROWTH
# (default 0.10 = 10 %) above the RSS at the end of pass 2 (docs/robustness.md, "Soak"). Pass 1 is the
# baseline only for a 2-pass run: it builds the map, and the loop closure with its global BA lands at
# its very end, so the steady state starts with the first revisit.
#   scripts/soak.sh [passes]
# Environment:
#   DYNSYNTH_DATA   rendered dev sequences (default ~/dynsynth); plays office_a_loop_walking, or
#                   SOAK_SEQ (a path) when set; falls back to a ../shared/data/dynsynth cut
#   SOAK_BUILD      Release build dir (default build-soak)   SOAK_OUT  output (default $SOAK_BUILD/soak)
#   SOAK_MAX_GROWTH allowed relative growth, end of pass 2 -> end of the last pass (default 0.10)
#   SP_JOBS, SP_NICE  build jobs (default 2) and niceness (default 10)
# Extra arguments after PASSES go to `stillpoint run` (e.g. --dynamic flow).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
PASSES="${1:-3}"
shift || true
BUILD="${SOAK_BUILD:-$ROOT/build-soak}"
OUT="${SOAK_OUT:-$BUILD/soak}"
MAX_GROWTH="${SOAK_MAX_GROWTH:-0.10}"
JOBS="${SP_JOBS:-2}"
NICE="${SP_NICE:-10}"
SRC="${SOAK_SEQ:-${DYNSYNTH_DATA:-$HOME/dynsynth}/office_a_loop_walking}"
if [ ! -f "$SRC/rgb.txt" ]; then
  echo "soak: $SRC not found (render it, see ../shared/data/README.md); using the shared cut" >&2
  SRC="$ROOT/../shared/data/dynsynth/office_a_walking_xyz_150"
fi
SRC="$(cd "$SRC" && pwd)"
MODEL="$ROOT/../shared/models/yolox_nano.onnx"

# Release, the modules `stillpoint run` needs (place = libtorch and report = npm are not).
cmake -S "$ROOT" -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=Release \
  -DSP_ONLY_MODULES="common;geometry;io;eval;features;dynamic;map;optimize;tracking;mapping;loop;pipeline" >/dev/null
nice -n "$NICE" cmake --build "$BUILD" -j "$JOBS" --target stillpoint

# The looped sequence: lists with timestamps shifted by one pass length (+ one frame period) per
# pass, so they keep increasing; image paths go through a symlink to the original folder. Only the
# rows within half a frame period of the pass's colour frames are kept, so the shifted passes never
# overlap (groundtruth.txt starts before the first image) and depth still associates (the reader
# pairs rgb.txt and depth.txt by nearest stamp when there is no associations.txt).
SEQ="$OUT/seq"
rm -rf "$OUT" && mkdir -p "$SEQ"
ln -s "$SRC" "$SEQ/src"
[ -f "$SRC/camera.yaml" ] && cp "$SRC/camera.yaml" "$SEQ/"
read -r FIRST LAST PERIOD N_RGB < <(awk '!/^#/ && NF >= 2 { if (n == 0) f = $1; if (n == 1) p = $1 - f; l = $1; n++ }
  END { printf "%.6f %.6f %.6f %d\n", f, l, p, n }' "$SRC/rgb.txt")
SHIFT=$(awk -v f="$FIRST" -v l="$LAST" -v p="$PERIOD" 'BEGIN { printf "%.6f", l - f + p }')
for list in rgb depth groundtruth; do
  [ -f "$SRC/$list.txt" ] || continue
  awk -v passes="$PASSES" -v shift="$SHIFT" -v lo="$FIRST" -v hi="$LAST" -v p="$PERIOD" -v list="$list" '
    /^#/ { if (!hdr) print; next }
    NF >= 2 { row[++n] = $0; stamp[n] = $1 }
    END {
      for (k = 0; k < passes; k++)
        for (i = 1; i <= n; i++) {
          if (stamp[i] < lo - p / 2 || stamp[i] >= hi + p / 2) continue
          line = row[i]
          rest = substr(line, index(line, " ") + 1)
          if (list != "groundtruth") rest = "src/" rest
          printf "%.6f %s\n", stamp[i] + k * shift, rest
        }
    }' "$SRC/$list.txt" >"$SEQ/$list.txt"
done
echo "soak: $SRC ($N_RGB frames) x $PASSES -> $SEQ ($(grep -vc '^#' "$SEQ/rgb.txt") frames)"

ARGS=(--dataset "$SEQ" --out "$OUT/run" --no-progress)
[ -f "$MODEL" ] && ARGS+=(--detector-model "$MODEL")
t0=$SECONDS
rc=0
nice -n "$NICE" "$BUILD/apps/stillpoint/stillpoint" run "${ARGS[@]}" "$@" >"$OUT/run.log" 2>&1 || rc=$?
echo "soak: run exited $rc after $((SECONDS - t0)) s (log $OUT/run.log)"

# RSS at the end of each pass (the last sample at or before pass k's last frame) and the verdict.
python3 - "$OUT/run/stats.json" "$N_RGB" "$PASSES" "$MAX_GROWTH" "$rc" "$SEQ/rgb.txt" "$OUT/run/keyframes.txt" <<'EOF' | tee "$OUT/soak.txt"
import json, sys
stats_file, per_pass, passes, max_growth, rc = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4]), int(sys.argv[5])
def stamps(path):
    try:
        return [float(l.split()[0]) for l in open(path) if l.strip() and not l.startswith("#")]
    except OSError:
        return []
rgb, kfs = stamps(sys.argv[6]), stamps(sys.argv[7])
s = json.load(open(stats_file))
tl = s.get("rss_timeline_mib", [])
ok = rc == 0 and s.get("completed") is True and len(tl) >= 2
def at(frame):
    before = [r for f, r in tl[:-1] if f <= frame]
    return before[-1] if before else float("nan")
ends = [at((k + 1) * per_pass) for k in range(passes)]
for k, r in enumerate(ends):
    lo = rgb[k * per_pass] if k * per_pass < len(rgb) else float("inf")
    hi = rgb[(k + 1) * per_pass] if (k + 1) * per_pass < len(rgb) else float("inf")
    live = sum(1 for t in kfs if lo <= t < hi)
    print(f"soak: pass {k + 1}: RSS at its end {r:.0f} MiB, live keyframes created in it {live}")
base = 1 if passes >= 3 else 0
growth = ends[-1] / ends[base] - 1 if ends and ends[base] > 0 else float("nan")
print(f"soak: frames {tl[-1][0] if tl else 0}, keyframes {s.get('keyframes')} (created {s.get('keyframes_created')}), "
      f"map points {s.get('map_points')}, loops closed {s.get('loops_closed')}, lost {s.get('lost_frames')}, "
      f"peak RSS {s.get('peak_rss_mib', 0):.0f} MiB, after drain {tl[-1][1] if tl else 0:.0f} MiB, wall {s.get('wall_s', 0):.0f} s")
print(f"soak: growth end of pass {base + 1} -> end of pass {passes}: {100 * growth:+.1f} % (limit {100 * max_growth:.0f} %)")
print("soak: growth per pass " + ", ".join(f"{k} -> {k + 1} {100 * (ends[k] / ends[k - 1] - 1):+.1f} %" for k in range(1, len(ends))))
ok = ok and growth < max_growth
print("soak: " + ("PASSED" if ok else "FAILED"))
sys.exit(0 if ok else 1)
EOF
