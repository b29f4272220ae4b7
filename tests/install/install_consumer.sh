#!/usr/bin/env bash
# Installs the build into a fresh prefix, moves the prefix (so nothing can depend on where it was
# installed or on the source and build trees), builds tests/install/consumer against it with
# find_package(StillPoint) and runs it on the installed demo sequence, then runs the installed CLI.
#   install_consumer.sh BUILD_DIR SOURCE_DIR WORK_DIR
set -euo pipefail
build=$1 src=$2 work=$3
rm -rf "$work"
mkdir -p "$work"
cmake --install "$build" --prefix "$work/staged" >"$work/install.log"
mv "$work/staged" "$work/prefix"  # relocated: found data must come from beside the files themselves
prefix="$work/prefix"
unset STILLPOINT_DATA_DIR
for f in bin/stillpoint include/stillpoint/stillpoint.hpp include/stillpoint/version.hpp \
         share/stillpoint/config/stillpoint.yaml share/stillpoint/data/vocab/stillpoint_orb.spv \
         share/stillpoint/models/yolox_nano/yolox_nano.onnx share/stillpoint/models/yolox_nano/LICENSE \
         share/stillpoint/data/demo/walking_xyz_demo/associations.txt; do
  [ -e "$prefix/$f" ] || { echo "FAILED: $f not installed"; exit 1; }
done
ls "$prefix"/lib*/cmake/StillPoint/StillPointConfig.cmake "$prefix"/lib*/cmake/StillPoint/StillPointConfigVersion.cmake \
   "$prefix"/lib*/pkgconfig/stillpoint.pc "$prefix"/lib*/libstillpoint.so >/dev/null

# The library exports namespace stillpoint only.
leaked=$(nm -D --defined-only -C "$prefix"/lib*/libstillpoint.so | grep -c " sp::" || true)
[ "$leaked" = 0 ] || { echo "FAILED: libstillpoint.so exports $leaked sp:: symbols"; exit 1; }

# pkg-config finds it, relocated, with Eigen and OpenCV.
pc_flags=$(PKG_CONFIG_PATH=$(dirname "$(ls "$prefix"/lib*/pkgconfig/stillpoint.pc)") pkg-config --cflags --libs stillpoint)
pc_include=$(echo "$pc_flags" | tr ' ' '\n' | grep -m1 '^-I' | cut -c3-)
[ "$(realpath "$pc_include")" = "$(realpath "$prefix/include")" ] \
  || { echo "FAILED: pkg-config stillpoint gives -I$pc_include, not the prefix's include/"; exit 1; }
echo "$pc_flags" | grep -q -- "-lstillpoint" && echo "$pc_flags" | grep -q -- "eigen3" \
  || { echo "FAILED: pkg-config stillpoint lacks -lstillpoint or Eigen: $pc_flags"; exit 1; }

cmake -S "$src/tests/install/consumer" -B "$work/consumer-build" -G Ninja -DCMAKE_BUILD_TYPE=Release \
  -DCMAKE_PREFIX_PATH="$prefix" >"$work/consumer-configure.log"
cmake --build "$work/consumer-build" >"$work/consumer-build.log"
demo="$prefix/share/stillpoint/data/demo/walking_xyz_demo"
cd "$work"
"$work/consumer-build/consumer" "$demo"

# The installed CLI: --version, and a short run that takes config, vocabulary, detector and the demo
# from the (moved) prefix.
"$prefix/bin/stillpoint" --version | grep -q "^stillpoint [0-9]" || { echo "FAILED: --version"; exit 1; }
"$prefix/bin/stillpoint" --log-level warn run --max-frames 20 --no-progress --deterministic --out "$work/run" >"$work/run.log"
python3 - "$work/run/stats.json" "$prefix" <<'PY'
import json, sys
s, prefix = json.load(open(sys.argv[1])), sys.argv[2]
for key in ("dataset", "config", "detector_model"):
    assert s[key].startswith(prefix), f"FAILED: {key} {s[key]} is not inside the installed prefix {prefix}"
assert s["tracked_frames"] > 0, "FAILED: the installed CLI tracked nothing"
print("installed CLI: data from the prefix,", s["tracked_frames"], "frames tracked")
PY
[ -s "$work/run/trajectory_kitti.txt" ] || { echo "FAILED: no KITTI trajectory"; exit 1; }

# The installed Python module (when built) loads libstillpoint.so through its RPATH and finds the
# prefix's data from where it lies.
if module=$(ls "$prefix"/lib*/python3/dist-packages/stillpoint*.so 2>/dev/null); then
  py=python3
  [ -x /usr/bin/python3 ] && py=/usr/bin/python3  # the interpreter Debian's pybind11 build targets
  found=$(PYTHONPATH=$(dirname "$module") "$py" -c "import stillpoint; print(stillpoint.data_dir())")
  [ "$(realpath "$found")" = "$(realpath "$prefix/share/stillpoint")" ] \
    || { echo "FAILED: installed Python module finds data in $found"; exit 1; }
  echo "installed Python module: data from the prefix"
fi
echo "install_consumer: all checks passed"
