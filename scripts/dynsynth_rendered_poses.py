#!/usr/bin/env python3
"""Camera poses a dynsynth sequence was actually rendered with, as a TUM trajectory at its rgb stamps.

Why: dynsynth's groundtruth.txt evaluates CameraPath.pose() on the whole 100 Hz time grid, but each
image is rendered from pose() called with ONE time. For the 'loop' camera the walking head-bob
(8 mm at 1.8 Hz, scaled by the loop speed from np.gradient) vanishes when pose() gets one time,
so the ground truth carries a vertical bob that no image shows (docs/loop_sequences.md, "Ground truth
of office_a_loop_walking"). Comparing a trajectory with both files separates that artefact from
tracking error:

  scripts/dynsynth_rendered_poses.py --motion loop_walking --frames 1500 --out /tmp/rendered.txt
  stillpoint eval --gt /tmp/rendered.txt --est RUN/trajectory.txt

Needs the renderer (../shared/tools/dynsynth, or --dynsynth DIR) and its Python packages (numpy, cv2).
The scene, motion, frame count and seed must be those of the render (meta/info.json has them).
"""
import argparse
import os
import sys


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--dynsynth", default=os.path.join(here, "..", "..", "shared", "tools", "dynsynth"),
                    help="folder of dynsynth.py (default ../shared/tools/dynsynth)")
    ap.add_argument("--scene", default="office_a")
    ap.add_argument("--motion", required=True, help="e.g. loop_walking")
    ap.add_argument("--frames", type=int, required=True)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", required=True, help="TUM trajectory to write")
    a = ap.parse_args()
    if not os.path.isfile(os.path.join(a.dynsynth, "dynsynth.py")):
        sys.exit("dynsynth_rendered_poses: no dynsynth.py in %s (use --dynsynth DIR)" % a.dynsynth)
    sys.path.insert(0, a.dynsynth)
    import dynsynth  # noqa: E402  (the renderer, imported from its folder)
    import scenes  # noqa: E402

    seq = dynsynth.Sequence(scenes.build(a.scene), a.motion, a.frames, a.seed, "jpg")
    with open(a.out, "w") as f:
        f.write("# poses the images were rendered with: %s %s, %d frames, seed %d\n"
                "# timestamp tx ty tz qx qy qz qw\n" % (a.scene, a.motion, a.frames, a.seed))
        for tau in seq.tau_rgb:
            R, p = seq.cam.pose([float(tau)])  # one time, exactly as render_color() calls it
            q = dynsynth.R_to_quat(R)[0]
            f.write("%.6f %.6f %.6f %.6f %.6f %.6f %.6f %.6f\n" % ((seq.t_base + tau,) + tuple(p[0]) + tuple(q)))
    print("dynsynth_rendered_poses: %d poses -> %s" % (len(seq.tau_rgb), a.out))


if __name__ == "__main__":
    main()
