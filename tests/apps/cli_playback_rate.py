#!/usr/bin/env python3
"""`stillpoint run --playback-rate R` hands frames to SLAM no faster than R x their recorded pace (a live
camera's timing), and never drops one: on the built-in demo at R = 0.5, every frame is tracked and the run
takes at least (last stamp - first stamp) / 0.5 of wall time; stats.json records the rate. A lower bound
only: how fast SLAM itself is, is not asserted here.

usage: cli_playback_rate.py STILLPOINT_BINARY SCRATCH_DIR
"""
import json
import os
import shutil
import subprocess
import sys

RATE = 0.5  # slower than the recording: an unpaced run of these frames takes well under the span
FRAMES = 30


def main():
    binary, scratch = sys.argv[1], sys.argv[2]
    shutil.rmtree(scratch, ignore_errors=True)
    os.makedirs(scratch)
    out = os.path.join(scratch, "out")
    subprocess.run([binary, "run", "--playback-rate", str(RATE), "--max-frames", str(FRAMES), "--no-progress",
                    "--out", out], check=True, stdout=subprocess.DEVNULL)
    with open(os.path.join(out, "stats.json")) as f:
        stats = json.load(f)
    with open(os.path.join(out, "trajectory.txt")) as f:
        stamps = [float(line.split()[0]) for line in f if line.strip() and not line.startswith("#")]
    assert stats["frames"] == FRAMES, f"{stats['frames']} frames processed, expected {FRAMES} (none dropped)"
    assert stats["playback_rate"] == RATE, stats.get("playback_rate")
    span = (max(stamps) - min(stamps)) / RATE
    assert span > 0.1, f"too short a stamp span to test pacing: {span:.3f} s"
    assert stats["wall_s"] >= 0.95 * span, f"ran in {stats['wall_s']:.3f} s, the paced frames span {span:.3f} s"
    print(f"ok: {FRAMES} frames in {stats['wall_s']:.2f} s (paced span {span:.2f} s)")


if __name__ == "__main__":
    main()
