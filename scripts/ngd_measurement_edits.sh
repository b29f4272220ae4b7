#!/usr/bin/env bash
# Applies the two measurement-only edits scripts/speed_vs_ngd.sh and `stillpoint bench --peers ngdslam`
# need to NGD-SLAM's RGB-D example (no SLAM logic touched) and rebuilds it:
#   - the sleep to the recorded frame time runs only when NGD_NO_PACE is unset (flat-out runs);
#   - steady_clock stamps around the frame loop and SLAM.Shutdown() print
#     "loop wall: A s, with shutdown: B s" (FPS like ours: frames / wall of the loop and the drain).
# Idempotent: an example that already has them is left as is.
#
#   scripts/ngd_measurement_edits.sh [NGD_DIR]   (default: $NGD_DIR or ~/.cache/stillpoint-peers/ngdslam)
set -euo pipefail
dir="${1:-${NGD_DIR:-${XDG_CACHE_HOME:-$HOME/.cache}/stillpoint-peers/ngdslam}}"
src="$dir/Examples/RGB-D/rgbd_tum.cc"
[ -f "$src" ] || { echo "ngd_measurement_edits.sh: $src not found (build the peer first: ../shared/tools/peer_ngdslam/setup.sh)" >&2; exit 2; }
if grep -q "with shutdown" "$src"; then
  echo "ngd_measurement_edits.sh: $src already has the edits"
else
  python3 - "$src" <<'PY'
import sys
p = sys.argv[1]
s = open(p).read()
edits = [
    ("    cv::Mat imRGB, imD;\n",
     "    cv::Mat imRGB, imD;\n"
     "    // [measurement edit] wall of the frame loop and of the shutdown; NGD_NO_PACE skips the sleep\n"
     "    const auto loop_start = std::chrono::steady_clock::now();\n"
     "    const bool no_pace = getenv(\"NGD_NO_PACE\") != nullptr;\n"),
    ("        if(ttrack<T)\n", "        if(!no_pace && ttrack<T)\n"),
    ("    SLAM.Shutdown();\n",
     "    const auto loop_end = std::chrono::steady_clock::now();\n"
     "    SLAM.Shutdown();\n"
     "    cout << \"loop wall: \" << std::chrono::duration<double>(loop_end - loop_start).count()\n"
     "         << \" s, with shutdown: \"\n"
     "         << std::chrono::duration<double>(std::chrono::steady_clock::now() - loop_start).count()\n"
     "         << \" s\" << endl;\n"),
]
for old, new in edits:
    if s.count(old) != 1:
        sys.exit(f"ngd_measurement_edits.sh: expected exactly one '{old.strip()}' in {p}; the example changed")
    s = s.replace(old, new)
open(p, "w").write(s)
PY
  echo "ngd_measurement_edits.sh: edited $src"
fi
make -C "$dir/build" rgbd_tum
