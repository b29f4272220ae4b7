#!/usr/bin/env bash
# Screens a candidate setting against the shipped defaults before it is judged on fresh rooms (issue 13):
# deterministic runs of every sequence of a suite at several detector latencies (detections 0, 1, 2
# frames late, as on a threaded run), both sides with the same binary. One deterministic run changes
# by about 1 % of the suite's ATE sum when only the detections' timing changes (docs/results.md
# "Session 35"), so a screen at one latency cannot tell a rule worth ~1 % from no change; the sum over
# the latencies can do better. Prints per latency the ATE sums and how many sequences got better or
# worse (by more than 0.05 mm), then the total; writes the bench JSON under OUT.
# Usage: scripts/screen.sh SUITE_DIR "CANDIDATE RUN ARGS" [OUT_DIR] [LATENCIES]
#   e.g. scripts/screen.sh ~/room_suite/tune "--set dynamic.motion.suspect_band_share=0.05" screen_out "0 1 2"
set -euo pipefail
if (($# < 2)); then
  sed -n '2,10p' "$0" | sed 's/^# \{0,1\}//'
  exit 2
fi
root="$(cd "$(dirname "$0")/.." && pwd)"
B="${SP_BUILD_DIR:-$root/build}/apps/stillpoint/stillpoint"
SUITE="$1"
CAND="$2"
OUT="${3:-$root/screen_out}"
LATENCIES="${4:-0 1 2}"
[ -x "$B" ] || { echo "screen.sh: $B not built (scripts/build.sh)" >&2; exit 1; }
[ -d "$SUITE" ] || { echo "screen.sh: no suite folder $SUITE" >&2; exit 1; }
variants=()
for l in $LATENCIES; do
  variants+=(--variant "main@$l=--set dynamic.deterministic_detector_latency=$l")
  variants+=(--variant "cand@$l=--set dynamic.deterministic_detector_latency=$l $CAND")
done
"$B" bench --suite "$SUITE" --deterministic --out "$OUT" "${variants[@]}" >"$OUT.log" 2>&1 ||
  { tail -20 "$OUT.log" >&2; exit 1; }
python3 - "$OUT/bench.json" "$CAND" <<'PY'
import collections, json, sys
runs = json.load(open(sys.argv[1]))["runs"]
ate = collections.defaultdict(dict)  # latency -> side -> sequence -> cm
for r in runs:
    side, lat = r["variant"].split("@")
    ate[lat].setdefault(side, {})[r["sequence"]] = r["ate"]["rmse"] * 100 if r.get("ate") else float("inf")
print(f"candidate: {sys.argv[2]}")
print("| latency | main ATE sum cm | candidate ATE sum cm | change | better | worse |")
print("|---|---|---|---|---|---|")
total = [0.0, 0.0]
for lat in sorted(ate, key=int):
    m, c = ate[lat]["main"], ate[lat]["cand"]
    seqs = sorted(set(m) & set(c))
    sm, sc = sum(m[s] for s in seqs), sum(c[s] for s in seqs)
    better = sum(c[s] < m[s] - 0.005 for s in seqs)
    worse = sum(c[s] > m[s] + 0.005 for s in seqs)
    total[0] += sm
    total[1] += sc
    print(f"| {lat} | {sm:.3f} | {sc:.3f} | {100 * (sc / sm - 1):+.1f} % | {better} | {worse} |")
print(f"| all | {total[0]:.3f} | {total[1]:.3f} | {100 * (total[1] / total[0] - 1):+.1f} % | | |")
PY
