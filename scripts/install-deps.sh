#!/usr/bin/env bash
# Installs fmv3d's build and test dependencies from Debian 12 packages only.
# Idempotent: when every package is already present it prints nothing and exits 0.
set -euo pipefail

PACKAGES=(
  build-essential cmake ninja-build pkg-config
  libopencv-dev libceres-dev libeigen3-dev libopen3d-dev libgdal-dev libproj-dev
  libcli11-dev libspdlog-dev nlohmann-json3-dev libgtest-dev libgmock-dev libbenchmark-dev libtbb-dev
  libavformat-dev libavcodec-dev libavutil-dev libswscale-dev
  libtinygltf-dev
  libcpp-httplib-dev
  ffmpeg
  chromium
  clang-format clang-tidy
  clang libclang-rt-14-dev  # the sanitizer build (make test-asan) and make fuzz: clang with its runtimes and libFuzzer
)
# Optional yardstick for bench/ only (COLMAP 3.8, CPU); never needed to build or test.
if [[ "${FMV3D_WITH_COLMAP:-0}" == "1" ]]; then PACKAGES+=(colmap); fi
# `make test-tsan` only: LLVM's OpenMP runtime and its Archer tool (scripts/tsan-runtime.sh), dpkg-dev to unpack
# oneTBB's source package; `bench/memory.sh` plots with gnuplot when present.
if [[ "${FMV3D_WITH_TSAN:-0}" == "1" ]]; then PACKAGES+=(libomp5-14 libomp-14-dev dpkg-dev); fi

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done
[[ ${#missing[@]} -eq 0 ]] && exit 0

echo "install-deps: installing ${#missing[@]} package(s): ${missing[*]}"
SUDO=""
if [[ $(id -u) -ne 0 ]]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
echo "install-deps: done"
