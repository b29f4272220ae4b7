#!/usr/bin/env python3
"""Track a TUM-layout RGB-D sequence with StillPoint from Python and write the trajectory.

    python3 track_sequence.py [SEQUENCE_DIR] [--camera CAMERA.yaml] [--out trajectory.txt]

Without arguments it runs the bundled demo sequence. The camera file may be StillPoint's camera.yaml,
ORB-SLAM2/3 or stella_vslam settings. Needs the `stillpoint` module on PYTHONPATH (installed:
<prefix>/lib/python3/dist-packages; build tree: <build>/python/stillpoint_pkg) and python3-opencv."""
import argparse
import pathlib

import cv2
import numpy as np

import stillpoint


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sequence", nargs="?", help="folder with rgb/, depth/, associations.txt")
    ap.add_argument("--camera", help="camera file (default: SEQUENCE/camera.yaml)")
    ap.add_argument("--out", default="trajectory.txt", help="TUM trajectory to write")
    args = ap.parse_args()
    seq = pathlib.Path(args.sequence or pathlib.Path(stillpoint.data_dir()) / "data/demo/walking_xyz_demo")

    config = stillpoint.Config()  # the shipped defaults: YOLOX-nano + flow culling, loop closing
    config.camera = stillpoint.Camera.load(args.camera or seq / "camera.yaml")
    slam = stillpoint.System(config)
    slam.on_keyframe(lambda kf, t, T: print(f"keyframe {kf} at {t:.3f}: position {np.round(T[:3, 3], 3)}"))
    slam.on_loop_closure(lambda q, m, T, n: print(f"loop closed: {q:.3f} -> {m:.3f} ({n} inliers)"))

    for line in (seq / "associations.txt").read_text().splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        t, rgb, _, depth = line.split()[:4]
        color = cv2.imread(str(seq / rgb), cv2.IMREAD_COLOR)  # BGR, as StillPoint expects by default
        raw = cv2.imread(str(seq / depth), cv2.IMREAD_UNCHANGED)  # uint16, / depth_factor = metres
        r = slam.track(color, raw, float(t))
        if r.state != "ok":
            print(f"{float(t):.3f}: {r.state}")

    slam.shutdown()
    stamps, poses = slam.trajectory()
    with open(args.out, "w") as f:
        f.write("# timestamp tx ty tz qx qy qz qw\n")
        for t, T in zip(stamps, poses):
            q = rotation_to_quaternion(T[:3, :3])
            f.write(f"{t:.6f} {T[0, 3]:.6f} {T[1, 3]:.6f} {T[2, 3]:.6f} {q[0]:.6f} {q[1]:.6f} {q[2]:.6f} {q[3]:.6f}\n")
    stats = slam.statistics()
    print(f"{len(stamps)} poses -> {args.out}; {stats['keyframes']} keyframes, "
          f"{stats['culled_features_total']} features culled on moving people")


def rotation_to_quaternion(R):
    """(qx, qy, qz, qw) of a rotation matrix (Shepperd's method, no SciPy needed)."""
    w = np.sqrt(max(0.0, 1.0 + R[0, 0] + R[1, 1] + R[2, 2])) / 2
    x = np.sqrt(max(0.0, 1.0 + R[0, 0] - R[1, 1] - R[2, 2])) / 2
    y = np.sqrt(max(0.0, 1.0 - R[0, 0] + R[1, 1] - R[2, 2])) / 2
    z = np.sqrt(max(0.0, 1.0 - R[0, 0] - R[1, 1] + R[2, 2])) / 2
    x = np.copysign(x, R[2, 1] - R[1, 2])
    y = np.copysign(y, R[0, 2] - R[2, 0])
    z = np.copysign(z, R[1, 0] - R[0, 1])
    return x, y, z, w


if __name__ == "__main__":
    main()
