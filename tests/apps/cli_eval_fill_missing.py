#!/usr/bin/env python3
"""`stillpoint eval --fill-missing` scores an estimate that leaves lost frames out on every frame of the
sequence, by one rule for every system. A camera moving at constant velocity (2 cm and 1 degree about
y per frame): the estimate is exact but lacks frames 10-19. skip scores the 20 written frames (ATE 0);
interpolate fills the gap on the constant-velocity path (ATE 0 on all 30); hold repeats frame 9's
pose, 2-20 cm off the truth (ATE > 5 cm on all 30). With a maps file naming frames 20-29 another map,
the gap is held, not blended across maps; a maps file with the wrong line count is an error naming it.

usage: cli_eval_fill_missing.py STILLPOINT_BINARY SCRATCH_DIR
"""
import json
import math
import os
import shutil
import subprocess
import sys

FRAMES = 30
LOST = range(10, 20)


def pose(i):
    yaw = math.radians(i)
    return 1000.0 + i / 30.0, (0.02 * i, 0.0, 0.0), (0.0, math.sin(yaw / 2), 0.0, math.cos(yaw / 2))


def line(i):
    t, p, q = pose(i)
    return "%.6f %.9f %.9f %.9f %.9f %.9f %.9f %.9f\n" % ((t,) + p + q)


def evaluate(binary, scratch, est, *extra):
    out = os.path.join(scratch, "eval.json")
    r = subprocess.run([binary, "eval", "--gt", os.path.join(scratch, "seq"), "--est", est, "--json", out] +
                       list(extra), capture_output=True, text=True)
    if r.returncode != 0:
        return None, r.stdout + r.stderr
    with open(out) as f:
        return json.load(f), r.stdout


def main():
    binary, scratch = sys.argv[1], sys.argv[2]
    shutil.rmtree(scratch, ignore_errors=True)
    seq = os.path.join(scratch, "seq")
    os.makedirs(seq)
    with open(os.path.join(seq, "groundtruth.txt"), "w") as f:
        f.writelines(line(i) for i in range(FRAMES))
    with open(os.path.join(seq, "rgb.txt"), "w") as f:
        f.writelines("%.6f rgb/%d.png\n" % (pose(i)[0], i) for i in range(FRAMES))
    est = os.path.join(scratch, "est.txt")
    kept = [i for i in range(FRAMES) if i not in LOST]
    with open(est, "w") as f:
        f.writelines(line(i) for i in kept)

    skip, _ = evaluate(binary, scratch, est)
    assert skip["pairs"] == len(kept) and skip["ate"]["rmse"] < 1e-6, skip
    interp, text = evaluate(binary, scratch, est, "--fill-missing", "interpolate")
    assert interp["pairs"] == FRAMES, interp["pairs"]
    assert interp["ate"]["rmse"] < 1e-4, f"interpolated constant motion off by {interp['ate']['rmse']} m"
    assert "10 interpolated" in text, text
    hold, _ = evaluate(binary, scratch, est, "--fill-missing", "hold")
    assert hold["pairs"] == FRAMES and hold["ate"]["rmse"] > 0.05, hold["ate"]

    maps = os.path.join(scratch, "maps.txt")
    with open(maps, "w") as f:
        f.writelines("%.6f %d\n" % (pose(i)[0], 1 if i >= 20 else 0) for i in kept)
    between, text = evaluate(binary, scratch, est, "--fill-missing", "interpolate", "--maps", maps)
    assert "10 held, 0 interpolated" in text, text
    with open(maps, "w") as f:
        f.writelines("%.6f 0\n" % pose(i)[0] for i in kept[:5])
    failed, text = evaluate(binary, scratch, est, "--fill-missing", "interpolate", "--maps", maps)
    assert failed is None and "maps.txt" in text, text
    print(f"ok: skip {skip['ate']['rmse']:.2e} m on {skip['pairs']}, interpolate {interp['ate']['rmse']:.2e} m, "
          f"hold {hold['ate']['rmse']:.3f} m on {FRAMES}")


if __name__ == "__main__":
    main()
