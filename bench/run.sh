#!/usr/bin/env bash
# Re-runs the commands behind bench/RESULTS.md, one section per table, into OUT (default bench-out/).
#
#   bench/run.sh SECTION... [--out DIR]
#   SECTION: sparse-colmap sparse dense demo clip coverage align geo other          (phase 1 and the mesh tables)
#            console handtools field-telemetry survey selfcal reliability ci       (phase 2 tables)
#            all                                                                    (every section)
#
# Each section writes its workspaces and the evaluation JSON files (report/*_eval.json, compare.json, ...) under
# OUT/SECTION/ and prints where the figures are. Needs a built fmv3d and benchmarks (make bench); sparse-colmap and geo's COLMAP
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
    -h|--help) sed -n '2,11p' "$0"; exit 0 ;;
    all)
      sections+=(sparse-colmap sparse dense demo clip coverage align geo other)
      sections+=(console handtools field-telemetry survey selfcal reliability ci)
      shift
      ;;
    *) sections+=("$1"); shift ;;
  esac
done
[[ ${#sections[@]} -gt 0 ]] || { sed -n '2,11p' "$0" >&2; exit 2; }
[[ -x "$FMV3D" ]] || { echo "$FMV3D not built: make bench" >&2; exit 1; }
[[ -x "$here/build/bench/align_bench" ]] || { echo "benchmarks not built: make bench" >&2; exit 1; }
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
# GEO_ROWS=name,name runs some rows only (as COVERAGE_ROWS for coverage).
run_geo() {
  local d=$1 name args
  while IFS='|' read -r name args; do
    [[ -z ${GEO_ROWS:-} || ,$GEO_ROWS, == *,$name,* ]] || continue
    # shellcheck disable=SC2086
    "$FMV3D" -q synth --klv $args -o "$d/$name/S"
    timed "$FMV3D" reconstruct "$d/$name/S/flight.ts" -o "$d/$name/F"
    "$FMV3D" evaluate-geo "$d/$name/F" --truth "$d/$name/S"
    if command -v colmap >/dev/null; then "$here/bench/compare_colmap_georef.sh" "$d/$name/F" "$d/$name/S" || true; fi
  done <<'FLIGHTS'
defaults|--seed 1
grid|--path grid --seed 1
pass|--path pass --seed 1
town|--scene town --seed 1
town_s2|--scene town --seed 2
terrain|--scene terrain --seed 1
terrain_s2|--scene terrain --seed 2
utm32|--seed 3 --geo-origin 46.5,8.0,1500
telephoto|--path pass --radius 600 --altitude 350 --focal 2500 --frames 300 --fps 30 --size 640x360 --seed 3
FLIGHTS
}
run_other() {
  local d=$1
  "$FMV3D" calibrate --board 9x6 --square 0.025 "$DATA/calib/opencv-chessboard" -o "$d/cam.json"
  local video=${FMV3D_DECODE_BENCH_VIDEO:-/tmp/fmv3d-decode-bench-1080p.mp4}
  [[ -f $video ]] || ffmpeg -loglevel error -f lavfi -i testsrc2=size=1920x1080:rate=30 -t 600 -c:v libx264 \
    -preset ultrafast -pix_fmt yuv420p "$video"
  FMV3D_DECODE_BENCH_VIDEO=$video "$here/build/bench/decode_bench" || true
  "$here/build/bench/match_bench" || true
  "$here/build/bench/render_bench" || true
}

# Mesh and texture, the whole-scene coverage rows (evaluate-dense: seen surface, completeness, per-view coverage),
# for each flight kind of issue 22: orbits, a nadir grid, a straight pass, and an oblique clip toward a far horizon
# (an MP4, so reconstruct picks its keyframes). COVERAGE_ROWS=name,name runs some rows only.
run_coverage() {
  local d=$1 name args in
  while IFS='|' read -r name args; do
    [[ -z ${COVERAGE_ROWS:-} || ,$COVERAGE_ROWS, == *,$name,* ]] || continue
    # shellcheck disable=SC2086
    "$FMV3D" -q synth $args -o "$d/S_$name"
    in=$d/S_$name/frames
    [[ -f $d/S_$name/flight.mp4 ]] && in=$d/S_$name/flight.mp4
    timed "$FMV3D" reconstruct "$in" -o "$d/W_$name" --until mesh
    "$FMV3D" evaluate-dense "$d/W_$name" --truth "$d/S_$name"
    "$FMV3D" evaluate-dense "$d/W_$name" --truth "$d/S_$name" --mesh "$d/W_$name/mesh/poisson.ply"
  done <<'FLIGHTS'
town_orbit|--scene town --path orbit --frames 36 --size 960x540
terrain_orbit_s1|--scene terrain --path orbit --frames 30 --size 960x540 --seed 1
terrain_grid|--scene terrain --path grid --frames 40 --size 960x540 --seed 1
town_pass|--scene town --path pass --frames 40 --size 960x540 --seed 1
terrain_oblique_clip|--scene terrain --path oblique --frames 300 --fps 10 --size 960x540 --format mp4 --seed 1
FLIGHTS
}

# Console, 3D Tiles, COG: tiles and first-picture times in Chromium (node + playwright, as the browser tests),
# then the console's browser test.
run_console() {
  local d=$1
  node "$here/bench/console_web.mjs" --fmv3d "$FMV3D" --web "$here/build/web" --points 1000000,10000000 --runs 3
  node "$here/bench/console_web.mjs" --fmv3d "$FMV3D" --web "$here/build/web" --points 20000000 --runs 1
  ctest --test-dir "$here/build" -R 'Browser.Console' --output-on-failure | tee "$d/ctest.txt"
}

# Hand tools: tie points, GCPs and the calibration window, from the CLI and through the page.
run_handtools() {
  ctest --test-dir "$here/build" -R 'E2eHandTools|Browser.Handtools' -V | tee "$1/ctest.txt"
}

# Field inputs: the telemetry readers on the shared real files (seconds).
run_field_telemetry() {
  local d=$1 f
  for f in "$DATA"/photos/exif-gps/*.jpg; do "$FMV3D" -q telemetry "$f" -o "$d/$(basename "$f").json"; done
  "$FMV3D" -q telemetry "$DATA/fmv/gopro/max-heromode.mp4" -o "$d/max-heromode.json"
  "$FMV3D" -q telemetry "$DATA/fmv/kwiver/videos/aphill_klv_10s.ts" -o "$d/aphill_klv_10s.json"
  log "positions: $d/*.json (compare the photos with $DATA/photos/exif-gps/README*)"
}

# Field inputs and registration: the low-texture nadir survey (image chain with the focal guessed and stated;
# EXIF JPEGs through reconstruct with no option), the oblique action-camera clip, the real KLV clip's
# line-of-sight check.
run_survey() {
  local d=$1
  "$FMV3D" -q synth --scene sand --path grid --overlap 70,40 --frames 60 --size 1600x900 --altitude 110 --format jpg \
    --seed 3 -o "$d/sand"
  sfm_chain "$d/sand/frames" "$d/sand_guess" "$d/sand/truth"
  mkdir -p "$d/sand_focal" && cp -r "$d/sand_guess"/{frames,features,matches} "$d/sand_focal"/
  timed "$FMV3D" -q sparse "$d/sand_focal" --focal 1385.6406  # the focal an EXIF would give
  "$FMV3D" evaluate-sparse "$d/sand_focal" --truth "$d/sand/truth"
  "$FMV3D" -q synth --scene sand --path grid --overlap 70,40 --frames 60 --size 1600x900 --altitude 110 \
    --exif-gps --gps-noise 3 --seed 3 -o "$d/sand_exif"
  timed "$FMV3D" reconstruct "$d/sand_exif/frames" -o "$d/sand_exif_ws" --until georef
  "$FMV3D" evaluate-sparse "$d/sand_exif_ws" --truth "$d/sand_exif/truth"
  "$FMV3D" dsm "$d/sand_exif_ws" && "$FMV3D" evaluate-geo "$d/sand_exif_ws" --truth "$d/sand_exif"
  "$FMV3D" -q synth --scene terrain --path oblique --frames 120 --fps 10 --size 854x480 --focal 450 \
    --distortion -0.27,0.08,0,0 --gpmf --gps-noise 3 --seed 4 -o "$d/obl"
  timed "$FMV3D" reconstruct "$d/obl/flight.mp4" -o "$d/obl_ws" --until georef --no-report
  "$FMV3D" evaluate-sparse "$d/obl_ws" --truth "$d/obl/truth"
  timed "$FMV3D" reconstruct "$DATA/fmv/kwiver/videos/aphill_klv_10s.ts" -o "$d/aphill"
  log "line of sight: $d/aphill/geo/georef.json (\"trusted\", \"line_of_sight\")"
}

# Self-calibration: the Strecha sets beside COLMAP (as sparse-colmap), the principal-point orbit, the focal scan on
# a flat curve, and the merged-model figures of E2eAlign.
run_selfcal() {
  local d=$1 set
  for set in fountain-P11 Herz-Jesus-P8; do
    "$FMV3D" -q import-truth strecha "$DATA/mvs/$set/gt_dense_cameras" -o "$d/$set-truth"
    "$here/bench/compare_colmap.sh" "$DATA/mvs/$set/images" --truth "$d/$set-truth" --out "$d/$set"
  done
  "$FMV3D" -q synth --scene town --path orbit --frames 24 --size 640x360 --seed 7 --principal-offset 12,-16 \
    --no-scene -o "$d/pp"
  sfm_chain "$d/pp/frames" "$d/pp_ws" "$d/pp/truth"
  "$FMV3D" -q synth --scene town --path orbit --frames 16 --size 640x360 --seed 3 -o "$d/scan"
  sfm_chain "$d/scan/frames" "$d/scan_ws" "$d/scan/truth"
  "$here/build/tests/test_e2e" --gtest_filter='E2eAlign*'
}

# Reliability: two uninterrupted runs of one flight compared byte for byte, then the crash-safety tests.
run_reliability() {
  local d=$1
  export SOURCE_DATE_EPOCH=1767225600 # the LAS header's creation day, as both runs must write the same bytes
  "$FMV3D" -q synth --scene building --path orbit --frames 90 --fps 10 --size 320x180 --klv --seed 5 -o "$d/S"
  timed "$FMV3D" -q reconstruct "$d/S/flight.ts" -o "$d/A" --fast --no-report
  timed "$FMV3D" -q reconstruct "$d/S/flight.ts" -o "$d/B" --fast --no-report
  # Products must match byte for byte; JSON summaries once every key naming seconds or a time is dropped and the
  # workspace's own path is taken out of the strings (report/timings.json holds times only).
  python3 - "$d/A" "$d/B" <<'PY' && log "reliability: every product identical"
import json, os, sys
a_root, b_root = sys.argv[1:]
def strip(v, root):
    if isinstance(v, dict):
        return {k: strip(x, root) for k, x in v.items() if "second" not in k and "time" not in k and k != "cpu_s"}
    if isinstance(v, list):
        return [strip(x, root) for x in v]
    return v.replace(root, "WS") if isinstance(v, str) else v
bad = 0
for dirpath, _, files in os.walk(a_root):
    for name in files:
        if name.endswith((".log", ".jsonl", ".lock")) or name == "timings.json":
            continue
        a = os.path.join(dirpath, name)
        rel = os.path.relpath(a, a_root)
        b = os.path.join(b_root, rel)
        if not os.path.exists(b):
            same = False
        elif name.endswith(".json"):
            same = strip(json.load(open(a)), a_root) == strip(json.load(open(b)), b_root)
        else:
            same = open(a, "rb").read() == open(b, "rb").read()
        if not same:
            print("differs:", rel, file=sys.stderr)
            bad = 1
sys.exit(bad)
PY
  ctest --test-dir "$here/build" -R CrashSafety --output-on-failure | tee "$d/ctest.txt"
}

# Tests and CI: a from-scratch Release build as CI makes it (unity + precompiled header, ccache off), then the
# whole suite, both timed. Takes ~35 min on 2 cores.
run_ci() {
  local d=$1
  cmake -S "$here" -B "$d/B" -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
  CCACHE_DISABLE=1 timed cmake --build "$d/B" -j2 >"$d/build.txt"
  timed ctest --test-dir "$d/B" -j2 | tee "$d/ctest.txt"
}

for s in "${sections[@]}"; do
  fn=run_${s//-/_}
  declare -F "$fn" >/dev/null || { echo "unknown section: $s" >&2; exit 2; }
  mkdir -p "$out/$s"
  log "$s → $out/$s"
  "$fn" "$out/$s" 2>&1 | tee "$out/$s/log.txt"
done
