#!/usr/bin/env bash
# Installs the Debian 12 packages StillPoint needs. Idempotent: does nothing when all are present.
set -euo pipefail
PACKAGES=(
  build-essential cmake ninja-build pkg-config
  libopencv-dev libeigen3-dev libceres-dev libtorch-dev
  libyaml-cpp-dev libspdlog-dev libfmt-dev libcli11-dev nlohmann-json3-dev
  libgloo-dev  # gloo headers for libtorch's c10d ProcessGroupGloo (data-parallel vpr train)
  libgtest-dev libgmock-dev libbenchmark-dev libopenni2-dev
  libjpeg-dev  # colour JPEGs decoded straight to BGR (src/stillpoint/io/jpeg_reader.cpp)
  chromium nodejs  # report: headless-browser test; npm fetches three.js at build time
  python3-opencv python3-numpy ccache  # scripts/room_suite.sh renders with dynsynth; ccache speeds rebuilds
  python3-onnx  # scripts/make_yolov7_tiny_onnx.py (YOLOv7-tiny graph with random weights, tests/dynamic)
  pybind11-dev python3-dev python3-pytest  # the Python bindings (python/) and their pytest tests
  clang libclang-rt-14-dev  # sanitizer builds and libFuzzer targets (scripts/sanitize.sh, scripts/fuzz.sh)
  $(command -v npm >/dev/null || echo npm)  # NodeSource's nodejs ships npm and conflicts with Debian's
)
missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "setup: installing ${missing[*]}"
  SUDO=""
  [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -q
  $SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
fi
