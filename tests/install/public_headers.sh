#!/usr/bin/env bash
# The public headers compile on their own with only Eigen, OpenCV and the standard library: compile
# include/stillpoint/stillpoint.hpp with just those include paths and check every header it pulls in
# (gcc -M) comes from Eigen, OpenCV, the C/C++ standard library or include/stillpoint itself.
#   public_headers.sh CXX SOURCE_DIR BUILD_DIR EIGEN_INCLUDE OPENCV_INCLUDE
set -euo pipefail
cxx=$1 src=$2 build=$3 eigen=$4 opencv=$5
unit='#include <stillpoint/stillpoint.hpp>
#include <stillpoint/version.hpp>'
deps=$(echo "$unit" | "$cxx" -std=c++17 -M -I"$src/include" -I"$build/include" -I"$eigen" -I"$opencv" -x c++ -)
echo "$unit" | "$cxx" -std=c++17 -fsyntax-only -Wall -Wextra -Wpedantic -Werror -I"$src/include" \
  -I"$build/include" -isystem "$eigen" -isystem "$opencv" -x c++ -
bad=0 n=0
for f in $(echo "$deps" | tr -d '\\' | tr ' ' '\n' | grep -E '\.(h|hpp|hh|tcc)$|/c\+\+/|/include/' || true); do
  n=$((n + 1))
  case "$(realpath -m "$f")" in
    "$src"/include/stillpoint/* | "$build"/include/stillpoint/*) ;;
    "$(realpath -m "$eigen")"/* | "$(realpath -m "$opencv")"/*) ;;
    /usr/include/c++/* | /usr/lib/gcc/* | /usr/include/*-linux-gnu/*) ;;
    /usr/include/linux/* | /usr/include/asm-generic/* | /usr/include/asm/* | /usr/include/sys/* | /usr/include/bits/*) ;;  # libc
    /usr/include/*/*) echo "not allowed in a public header: $f"; bad=1 ;;  # a library's own folder
    /usr/include/*) ;;  # the C library's headers
    *) echo "not allowed in a public header: $f"; bad=1 ;;
  esac
done
[ "$n" -gt 50 ] || { echo "FAILED: gcc -M listed only $n headers"; exit 1; }
[ "$bad" = 0 ] || { echo "FAILED: the public header pulls in more than Eigen, OpenCV and std"; exit 1; }
echo "public headers: $n headers, all from Eigen, OpenCV, the standard library or include/stillpoint"
