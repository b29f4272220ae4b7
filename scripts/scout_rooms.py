#!/usr/bin/env python3
"""Estimates how much of the view people cover in dynsynth random rooms, without rendering them.

    scripts/scout_rooms.py --seeds 309-400 [--motions walking_xyz,walking_rpy] [--frames 400] [--step 4]

For each room seed and motion it builds the sequence exactly as `dynsynth.py render` would (same camera
path, same people), traces every STEP-th frame at 160x120 without shading, and prints one line:
seed, motion, mean people cover, share of frames over half covered. About a second per sequence
instead of minutes of rendering, so a judge can select crowded sequences before any is rendered
(docs/results.md, "Session 39": matches the renderer's people_cover_mean to 0.001 on rooms 284, 296,
281). Seeds whose room cannot be built are reported on stderr and skipped.
Needs the dynsynth tool (DYNSYNTH_TOOL, default ../shared/tools/dynsynth/dynsynth.py) and its Python
packages (numpy, OpenCV).
"""
import argparse
import os
import sys


def parse_seeds(text):
    seeds = []
    for part in text.split(","):
        if "-" in part:
            a, b = part.split("-")
            seeds.extend(range(int(a), int(b) + 1))
        elif part:
            seeds.append(int(part))
    return seeds


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", required=True, help="room seeds, e.g. 309-400 or 101,105,110-112")
    ap.add_argument("--motions", default="walking_xyz,walking_rpy,walking_halfsphere",
                    help="comma-separated dynsynth motions (default: the three moving-camera walking ones)")
    ap.add_argument("--frames", type=int, default=400, help="frames of the sequence (as rendered)")
    ap.add_argument("--step", type=int, default=4, help="trace every STEP-th frame")
    a = ap.parse_args()
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    tool = os.environ.get("DYNSYNTH_TOOL", os.path.join(root, "..", "shared", "tools", "dynsynth", "dynsynth.py"))
    if not os.path.isfile(tool):
        sys.exit("scout_rooms: dynsynth not found at %s (set DYNSYNTH_TOOL)" % tool)
    sys.path.insert(0, os.path.dirname(os.path.abspath(tool)))
    import numpy as np  # noqa: E402
    import dynsynth as ds  # noqa: E402
    import scenes  # noqa: E402

    print("# seed motion people_cover_mean frames_over_half_covered")
    for seed in parse_seeds(a.seeds):
        for motion in filter(None, a.motions.split(",")):
            try:
                seq = ds.Sequence(scenes.build("random", seed), motion, a.frames, seed, "jpg")
            except (RuntimeError, SystemExit) as e:
                print("scout_rooms: seed %d %s: %s" % (seed, motion, e), file=sys.stderr)
                continue
            # A low-resolution tracer over the same scene: only which surface each ray hits is needed.
            renderer = ds.Renderer(seq.scene, seq.sprites, K=ds.TUM.scaled(160, 120))
            cover = []
            for k in range(0, a.frames, a.step):
                tau = float(seq.tau_rgb[k])
                R, p = seq.cam.pose([tau])
                _, _, face = renderer.trace(R[0], p[0], ds.people_at(seq.pts, seq.tracks, tau))
                cover.append(float((face >= seq.scene.n_static).mean()))
            cover = np.array(cover)
            print("%d %s %.3f %.3f" % (seed, motion, cover.mean(), (cover > 0.5).mean()), flush=True)


if __name__ == "__main__":
    main()
