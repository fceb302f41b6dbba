#!/usr/bin/env bash
# CPU seconds (user + system of every compiler and linker) of a from-scratch build, ccache off, so the figure
# holds on a loaded machine, where wall time does not.
#   bench/build_cpu.sh DIR [cmake -D options ...] [-- ninja targets or object files ...]
# e.g. bench/build_cpu.sh /tmp/b-unity -DFMV3D_UNITY=ON            (the whole Release build, as `make test` does)
#      bench/build_cpu.sh /tmp/b-plain -DFMV3D_UNITY=OFF -- fmv3d_core fmv3d_io
# DIR is emptied first. Prints the wall, user and system seconds and the number of compile steps.
set -euo pipefail
dir=$1
shift
cmake_args=()
while [[ $# -gt 0 && $1 != "--" ]]; do
  cmake_args+=("$1")
  shift
done
[[ $# -gt 0 ]] && shift
src=$(cd "$(dirname "$0")/.." && pwd)
rm -rf "$dir"
cmake -S "$src" -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=Release "${cmake_args[@]}" >/dev/null
export CCACHE_DISABLE=1
/usr/bin/time -f "build: %e s wall, %U s user, %S s sys" ninja -C "$dir" -j "${JOBS:-2}" "$@" >"$dir/build.log" 2>&1 || {
  tail -30 "$dir/build.log"
  exit 1
}
tail -1 "$dir/build.log"
echo "compile steps: $(grep -c 'Building CXX' "$dir/build.log"), link steps: $(grep -c 'Linking CXX' "$dir/build.log")"
