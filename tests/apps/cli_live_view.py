#!/usr/bin/env python3
"""The CLI's live view end to end: `stillpoint run --viewer 0` on the built-in demo, read as a browser
would (the page, then the Server-Sent Events stream) while the run goes on.

It asserts what a user watching sees: one pose event per frame in frame order with a pose for the
tracked ones, map snapshots with points, overlay images that are JPEGs, and an `end` event whose counts
match the run's stats.json. Standard library only.

usage: cli_live_view.py STILLPOINT_BINARY SCRATCH_DIR
"""
import base64
import json
import os
import re
import shutil
import socket
import subprocess
import sys


def http_get(port, path, until=None, timeout=120.0):
    """Raw HTTP GET on 127.0.0.1; reads until `until` appears or the server closes the connection."""
    with socket.create_connection(("127.0.0.1", port), timeout=timeout) as s:
        s.sendall(f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n".encode())
        data = b""
        while True:
            chunk = s.recv(65536)
            if not chunk:
                break
            data += chunk
            if until is not None and until in data:
                break
    return data.decode("utf-8", errors="replace")


def parse_events(stream):
    events = []
    for block in stream.split("\n\n"):
        kind = re.search(r"^event: (\w+)$", block, re.M)
        data = re.search(r"^data: (.*)$", block, re.M)
        if kind and data:
            events.append((kind.group(1), json.loads(data.group(1))))
    return events


def main():
    binary, scratch = sys.argv[1], sys.argv[2]
    shutil.rmtree(scratch, ignore_errors=True)
    os.makedirs(scratch)
    out = os.path.join(scratch, "run")
    run = subprocess.Popen([binary, "run", "--viewer", "0", "--no-progress", "--deterministic", "--out", out],
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    port = None
    lines = []
    for line in run.stdout:
        lines.append(line)
        m = re.search(r"live view: http://127\.0\.0\.1:(\d+)/", line)
        if m:
            port = int(m.group(1))
            break
    failures = []
    if port is None:
        run.wait()
        print("".join(lines))
        print("FAIL: the run never printed its live-view address")
        return 1

    page = http_get(port, "/", until=b"</html>")
    if not page.startswith("HTTP/1.1 200") or "new EventSource('/events')" not in page:
        failures.append("the page is not served or does not open the event stream")
    stream = http_get(port, "/events", until=b"event: end\n")
    rest, _ = run.communicate(timeout=600)
    lines.append(rest)
    if run.returncode != 0:
        failures.append(f"the run exited with {run.returncode}")

    events = parse_events(stream)
    poses = [e for kind, e in events if kind == "pose"]
    maps = [e for kind, e in events if kind == "map"]
    overlays = [e for kind, e in events if kind == "overlay"]
    ends = [e for kind, e in events if kind == "end"]
    stats = json.load(open(os.path.join(out, "stats.json")))

    frames = [p["frame"] for p in poses]
    if len(poses) != stats["frames"]:
        failures.append(f"{len(poses)} pose events for {stats['frames']} frames")
    if frames != sorted(set(frames)):
        failures.append("pose events are not one per frame in frame order")
    with_pose = [p for p in poses if "p" in p and "q" in p]
    if len(with_pose) != stats["tracked_frames"]:
        failures.append(f"{len(with_pose)} poses for {stats['tracked_frames']} tracked frames")
    for p in with_pose:
        norm = sum(x * x for x in p["q"]) ** 0.5
        if abs(norm - 1.0) > 1e-6 or len(p["p"]) != 3:
            failures.append(f"frame {p['frame']}: not a pose: {p}")
            break
    # The live poses are the tracker's; the written trajectory is the same after bundle adjustment moved
    # it a little (its world frame, not another).
    written = {}
    for line in open(os.path.join(out, "trajectory.txt")):
        if not line.startswith("#") and line.strip():
            v = [float(x) for x in line.split()]
            written[round(v[0], 6)] = v[1:4]
    worst = 0.0
    for p in with_pose:
        w = written.get(round(p["t"], 6))
        if w is None:
            failures.append(f"frame {p['frame']} (t {p['t']}) has a live pose but no trajectory line")
            break
        worst = max(worst, sum((a - b) ** 2 for a, b in zip(p["p"], w)) ** 0.5)
    if worst > 0.02:
        failures.append(f"live poses are up to {worst:.3f} m from the written trajectory")
    if not any(m["count"] > 0 and m["keyframe_count"] > 0 for m in maps):
        failures.append("no map event with points and keyframes")
    if not overlays or not all(base64.b64decode(o["jpeg"])[:3] == b"\xff\xd8\xff" for o in overlays):
        failures.append("no overlay event, or one that is not a JPEG")
    if len(ends) != 1 or ends[0]["frames"] != stats["frames"] or ends[0]["tracked"] != stats["tracked_frames"]:
        failures.append(f"end event {ends} does not match stats.json")

    print(f"live view: {len(poses)} poses ({len(with_pose)} tracked), {len(maps)} map events, "
          f"{len(overlays)} overlays, end {ends}, live vs written trajectory <= {worst * 1000:.2f} mm")
    for f in failures:
        print("FAIL:", f)
    if failures:
        print("".join(lines)[-4000:])
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
