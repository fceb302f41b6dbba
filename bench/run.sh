#!/usr/bin/env bash
# Re-runs the commands behind bench/RESULTS.md, one section per table, into OUT (default bench-out/).
#
#   bench/run.sh SECTION... [--out DIR]      SECTION: sparse-colmap sparse dense demo clip align geo other all
#
# Each section writes its workspaces and the evaluation JSON files (report/*_eval.json, compare.json, ...) under
# OUT/SECTION/ and prints where the figures are. Needs a built fmv3d (make build); sparse-colmap and geo's COLMAP
# column need `colmap` (FMV3D_WITH_COLMAP=1 scripts/install-deps.sh); sections on real data need ../shared/data.
# A section takes minutes to hours on 2 cores (dense and geo the longest); run them on a quiet machine.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
FMV3D=${FMV3D:-$here/build/fmv3d}
DATA=${FMV3D_DATA:-$here/../shared/data}
out=$here/bench-out
sections=()
while [[ $# -gt 0 ]]; do
  case "$1" in
    --out) out=$2; shift 2 ;;
    -h|--help) sed -n '2,9p' "$0"; exit 0 ;;
    all) sections+=(sparse-colmap sparse dense demo clip align geo other); shift ;;
    *) sections+=("$1"); shift ;;
  esac
done
[[ ${#sections[@]} -gt 0 ]] || { sed -n '2,9p' "$0" >&2; exit 2; }
[[ -x "$FMV3D" ]] || { echo "$FMV3D not built: make build" >&2; exit 1; }
log() { echo "[bench] $*" >&2; }
timed() { /usr/bin/time -f '%e s wall, %U+%S CPU-s, %M kB peak' "$@"; }

sfm_chain() {  # sfm_chain INPUT WS TRUTH [match options]
  local in=$1 ws=$2 truth=$3; shift 3
  "$FMV3D" -q frames "$in" -o "$ws" && "$FMV3D" -q features "$ws" && "$FMV3D" -q match "$ws" "$@" &&
    timed "$FMV3D" -q sparse "$ws" && "$FMV3D" evaluate-sparse "$ws" --truth "$truth"
}
truth_cams_ws() {  # a workspace whose sparse model is synth's true cameras
  mkdir -p "$2/sparse" && cp "$1"/truth/* "$2/sparse" && ln -sfn "$(cd "$1" && pwd)/frames" "$2/frames"
}

run_sparse_colmap() {
  local d=$1
  "$FMV3D" -q import-truth strecha "$DATA/mvs/fountain-P11/gt_dense_cameras" -o "$d/fountain_truth"
  "$here/bench/compare_colmap.sh" "$DATA/mvs/fountain-P11/images" --truth "$d/fountain_truth" --out "$d/fountain"
  "$FMV3D" -q import-truth strecha "$DATA/mvs/Herz-Jesus-P8/gt_dense_cameras" -o "$d/herz_truth"
  "$here/bench/compare_colmap.sh" "$DATA/mvs/Herz-Jesus-P8/images" --truth "$d/herz_truth" --out "$d/herz"
  "$FMV3D" -q synth --scene town --path orbit --frames 40 --size 960x540 --distortion -0.08,0,0,0 --seed 5 -o "$d/o40"
  "$here/bench/compare_colmap.sh" "$d/o40/frames" --truth "$d/o40/truth" --out "$d/o40cmp"
  "$FMV3D" -q synth --scene building --path orbit --frames 600 --fps 10 --size 960x540 --format mp4 -o "$d/clip60"
  "$here/bench/compare_colmap.sh" "$d/clip60/flight.mp4" --truth "$d/clip60/truth" --matcher sequential --out "$d/clipcmp"
}
run_sparse() {
  local d=$1
  "$FMV3D" -q synth --scene town --path orbit --frames 80 --size 1280x720 --distortion -0.08,0,0,0 --seed 3 -o "$d/o80"
  sfm_chain "$d/o80/frames" "$d/o80ws" "$d/o80/truth"
  "$FMV3D" -q synth --scene terrain --path grid --frames 40 --size 960x540 --distortion -0.05,0,0,0 --seed 2 -o "$d/g40"
  sfm_chain "$d/g40/frames" "$d/g40ws" "$d/g40/truth"
  for set in fountain-P11 Herz-Jesus-P8; do
    "$FMV3D" -q import-truth strecha "$DATA/mvs/$set/gt_dense_cameras" -o "$d/$set-truth"
    sfm_chain "$DATA/mvs/$set/images" "$d/$set" "$d/$set-truth"
  done
}
run_dense() {
  local d=$1
  "$FMV3D" -q synth --scene town --path orbit --frames 24 --size 1280x720 -o "$d/T"
  truth_cams_ws "$d/T" "$d/Wtruth"
  timed "$FMV3D" dense "$d/Wtruth" --max-size 1280 && "$FMV3D" evaluate-dense "$d/Wtruth" --truth "$d/T"
  sfm_chain "$d/T/frames" "$d/Wours" "$d/T/truth"
  timed "$FMV3D" dense "$d/Wours" --max-size 1280 && "$FMV3D" evaluate-dense "$d/Wours" --truth "$d/T"
}
run_demo() { timed "$FMV3D" demo -o "$1/demo"; }
run_clip() {
  local d=$1
  "$FMV3D" -q synth --scene building --path orbit --frames 600 --fps 10 --size 960x540 --format mp4 -o "$d/clip60"
  timed "$FMV3D" reconstruct "$d/clip60/flight.mp4" -o "$d/fast" --fast
  "$FMV3D" evaluate-sparse "$d/fast" --truth "$d/clip60/truth"
  "$FMV3D" evaluate-texture "$d/fast" --truth "$d/clip60"
  "$FMV3D" evaluate-dense "$d/fast" --truth "$d/clip60"
}
run_align() {
  FMV3D_ALIGN_BENCH_DIR=$1/align "$here/build/bench/align_bench" --benchmark_filter=TwoFlights
  "$here/build/tests/test_e2e" --gtest_filter='E2eAlign*'
}
run_geo() {
  local d=$1 name args
  while IFS='|' read -r name args; do
    # shellcheck disable=SC2086
    "$FMV3D" -q synth --klv --seed 1 $args -o "$d/$name/S"
    timed "$FMV3D" reconstruct "$d/$name/S/flight.ts" -o "$d/$name/F"
    "$FMV3D" evaluate-geo "$d/$name/F" --truth "$d/$name/S"
    if command -v colmap >/dev/null; then "$here/bench/compare_colmap_georef.sh" "$d/$name/F" "$d/$name/S" || true; fi
  done <<'FLIGHTS'
defaults|
grid|--path grid
pass|--path pass
town|--scene town
terrain|--scene terrain
FLIGHTS
}
run_other() {
  local d=$1
  "$FMV3D" calibrate --board 9x6 --square 0.025 "$DATA/calib/opencv-chessboard" -o "$d/cam.json"
  "$here/build/bench/decode_bench" || true
  "$here/build/bench/match_bench" || true
  "$here/build/bench/render_bench" || true
}

for s in "${sections[@]}"; do
  fn=run_${s//-/_}
  declare -F "$fn" >/dev/null || { echo "unknown section: $s" >&2; exit 2; }
  mkdir -p "$out/$s"
  log "$s → $out/$s"
  "$fn" "$out/$s" 2>&1 | tee "$out/$s/log.txt"
done
