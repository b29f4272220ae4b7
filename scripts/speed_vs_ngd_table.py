#!/usr/bin/env python3
"""Table of scripts/speed_vs_ngd.sh OUT: per sequence and mode, ours vs NGD-SLAM: ATE RMSE (cm, median and
range over the runs, NGD-SLAM's scored with `stillpoint eval` against the sequence's ground truth), FPS and
tracking-thread median ms (medians over the runs). Writes OUT/speed_vs_ngd.json too.

usage: speed_vs_ngd_table.py OUT [STILLPOINT_BINARY]"""
import glob
import json
import os
import re
import statistics as st
import subprocess
import sys

out = sys.argv[1]
binary = sys.argv[2] if len(sys.argv) > 2 else os.path.join(os.path.dirname(__file__), "..", "build", "apps",
                                                             "stillpoint", "stillpoint")
runs = {}  # (sequence, system, mode) -> list of (ate_cm, fps, trk_ms, lost)
stopped = []  # our runs that did not complete, with the reason stats.json gives
for d in glob.glob(os.path.join(out, "*__ours_*__*")):
    if not os.path.isdir(d):
        continue  # the run's log

    seq, kind, _ = os.path.basename(d).split("__")
    try:
        j = json.load(open(os.path.join(d, "stats.json")))
    except (OSError, ValueError):
        continue
    if not j.get("completed", True):
        stopped.append((os.path.basename(d), j.get("stop_reason", "no reason recorded")))
    runs.setdefault((seq, "ours", kind[5:]), []).append(
        (j["eval"]["ate"]["rmse"] * 100, j["fps"], j["stages_ms"]["frame"]["median_ms"], j["lost_frames"],
         j["dataset"]))
for f in glob.glob(os.path.join(out, "*__ngd_*__*.txt")):
    if not os.path.exists(f[:-4] + ".out"):
        continue  # run.sh's side files (keyframes, settings)
    seq, kind, _ = os.path.basename(f)[:-4].split("__")
    log = open(f[:-4] + ".out").read() + (open(f + ".log").read() if os.path.exists(f + ".log") else "")
    med = re.search(r"median tracking time:\s*([0-9.eE+-]+)", log)
    wall = re.search(r"with shutdown:\s*([0-9.]+)", log)
    frames = sum(1 for line in open(f) if line.strip() and not line.startswith("#"))
    seq_dirs = [d for d in glob.glob(os.path.join(out, seq + "__ours_*")) if os.path.exists(d + "/stats.json")]
    if not seq_dirs:
        continue
    dataset = json.load(open(seq_dirs[0] + "/stats.json"))["dataset"]
    ev = os.path.join(out, "_eval.json")
    subprocess.run([binary, "eval", "--gt", dataset, "--est", f, "--json", ev], capture_output=True)
    try:
        ate = json.load(open(ev))["ate"]["rmse"] * 100
    except (OSError, ValueError, KeyError):
        ate = float("nan")
    n_total = sum(1 for line in open(os.path.join(dataset, "rgb.txt")) if line.strip() and not line.startswith("#"))
    runs.setdefault((seq, "ngd", kind[4:]), []).append(
        (ate, frames / float(wall.group(1)) if wall else float("nan"),
         float(med.group(1)) * 1000 if med else float("nan"), n_total - frames, dataset))

table = []
for seq in sorted({k[0] for k in runs}):
    for mode in ("flat", "realtime"):
        row = {"sequence": seq, "mode": mode}
        for system in ("ours", "ngd"):
            v = runs.get((seq, system, mode), [])
            if not v:
                continue
            a = [x[0] for x in v]
            row[system] = {"runs": len(v), "ate_cm": st.median(a), "ate_min": min(a), "ate_max": max(a),
                           "fps": st.median([x[1] for x in v]), "trk_ms": st.median([x[2] for x in v]),
                           "lost": sum(x[3] for x in v)}
        if "ours" in row or "ngd" in row:
            table.append(row)
json.dump(table, open(os.path.join(out, "speed_vs_ngd.json"), "w"), indent=1)


def cell(r, k, fmt):
    return fmt.format(r[k]) if r else "-"


print("| sequence | mode | ours ATE cm [range] | NGD ATE cm [range] | ours FPS | NGD FPS | ours trk ms | NGD trk ms "
      "| ours lost | NGD lost/missing | runs |")
print("|---|---|---|---|---|---|---|---|---|---|---|")
for row in table:
    o, g = row.get("ours"), row.get("ngd")
    rng = lambda r: f"{r['ate_cm']:.2f} [{r['ate_min']:.2f}-{r['ate_max']:.2f}]" if r else "-"
    print(f"| {row['sequence']} | {row['mode']} | {rng(o)} | {rng(g)} | {cell(o, 'fps', '{:.1f}')} | "
          f"{cell(g, 'fps', '{:.1f}')} | {cell(o, 'trk_ms', '{:.1f}')} | {cell(g, 'trk_ms', '{:.1f}')} | "
          f"{cell(o, 'lost', '{}')} | {cell(g, 'lost', '{}')} | {o['runs'] if o else 0}/{g['runs'] if g else 0} |")
for mode in ("flat", "realtime"):
    rows = [r for r in table if r["mode"] == mode and "ours" in r and "ngd" in r]
    if not rows:
        continue
    fps_ok = sum(r["ours"]["fps"] >= r["ngd"]["fps"] for r in rows)
    trk_ok = sum(r["ours"]["trk_ms"] <= r["ngd"]["trk_ms"] for r in rows)
    ate_ok = sum(r["ours"]["ate_cm"] <= r["ngd"]["ate_cm"] for r in rows)
    print(f"\n{mode}: ours FPS >= NGD on {fps_ok}/{len(rows)}; ours tracking median <= NGD on {trk_ok}/{len(rows)}; "
          f"ours ATE <= NGD on {ate_ok}/{len(rows)}")
for name, why in sorted(stopped):
    print(f"stopped early: {name}: {why}")
