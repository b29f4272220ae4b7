#!/usr/bin/env bash
# Frame rate side by side with NGD-SLAM, like for like, on TUM-layout sequences:
#   flat out  - both process frames as fast as they can: ours `run` (no pacing), NGD-SLAM's rgbd_tum with
#               its per-frame sleep removed (NGD_NO_PACE=1, see below);
#   real time - both get frames at the recorded 30 Hz: ours `run --realtime`, NGD-SLAM's example as
#               upstream wrote it (it sleeps until the next frame's time stamp).
# FPS = frames / wall time of the frame loop plus the final drain of the mapping threads (ours: stats.json
# wall_s; NGD-SLAM: the "loop wall ... with shutdown" line); tracking ms = the tracking thread's median per
# frame (ours: stages_ms.frame; NGD-SLAM: its "median tracking time", which leaves out image loading).
#
#   scripts/speed_vs_ngd.sh OUT "SEQ_DIR..." [FLAT_REPS=3] [REALTIME_REPS=1]
#
# NGD-SLAM's example needs two measurement-only edits for this (no SLAM logic touched), applied to the
# peer build in ~/.cache/stillpoint-peers/ngdslam/Examples/RGB-D/rgbd_tum.cc and rebuilt with
# `make rgbd_tum` in its build folder: the usleep at the end of the frame loop runs only when
# getenv("NGD_NO_PACE") is unset, and steady_clock stamps around the loop and SLAM.Shutdown() print
# "loop wall: A s, with shutdown: B s". Without them the flat-out NGD runs are paced and print no wall.
# scripts/ngd_measurement_edits.sh applies both and rebuilds (idempotent; run it after every peer setup.sh).
# Run it on a quiet machine (nothing else busy); scripts/speed_vs_ngd_table.py OUT prints the table.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
out="${1:?usage: speed_vs_ngd.sh OUT \"SEQ_DIR...\" [FLAT_REPS] [REALTIME_REPS]}"
seqs="${2:?sequence folders}"
flat_reps="${3:-3}"
rt_reps="${4:-1}"
bin="${STILLPOINT_BIN:-$root/build/apps/stillpoint/stillpoint}"
config="${STILLPOINT_CONFIG:-$root/config/stillpoint.yaml}"
ngd="${NGD_RUN:-$root/../shared/tools/peer_ngdslam/run.sh}"
mkdir -p "$out"
for s in $seqs; do
  n="$(basename "$s")"
  for r in $(seq 1 "$flat_reps"); do
    "$bin" run --dataset "$s" --config "$config" --out "$out/${n}__ours_flat__$r" --no-progress \
      > "$out/${n}__ours_flat__$r.log" 2>&1 || true
    NGD_NO_PACE=1 NICE=0 "$ngd" "$s" "$out/${n}__ngd_flat__$r.txt" > "$out/${n}__ngd_flat__$r.out" 2>&1 || true
  done
  for r in $(seq 1 "$rt_reps"); do
    "$bin" run --dataset "$s" --config "$config" --realtime --out "$out/${n}__ours_realtime__$r" --no-progress \
      > "$out/${n}__ours_realtime__$r.log" 2>&1 || true
    NICE=0 "$ngd" "$s" "$out/${n}__ngd_realtime__$r.txt" > "$out/${n}__ngd_realtime__$r.out" 2>&1 || true
  done
done
