#!/usr/bin/env bash
# Side-by-side: COLMAP 3.8 (Debian package, CPU) and fmv3d on the same images, same machine, same run.
#
#   bench/compare_colmap.sh INPUT [--truth DIR] [--matcher exhaustive|sequential] [--out DIR]
#
# INPUT is a folder of images or a video file. --truth is a COLMAP text model of the true cameras (e.g. from
# `fmv3d synth` (DIR/truth) or `fmv3d import-truth strecha ...`), matched to our frames by image name.
# Prints time per stage, registered images, points, mean reprojection error and (with --truth) pose error for both.
# Needs `colmap` (FMV3D_WITH_COLMAP=1 scripts/install-deps.sh) and a built fmv3d (make build).
set -euo pipefail

here=$(cd "$(dirname "$0")/.." && pwd)
FMV3D=${FMV3D:-$here/build/fmv3d}
input=""; truth=""; matcher=auto; out=""
while [[ $# -gt 0 ]]; do
  case "$1" in
    --truth) truth=$2; shift 2 ;;
    --matcher) matcher=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    -h|--help) sed -n '2,9p' "$0"; exit 0 ;;
    *) input=$1; shift ;;
  esac
done
[[ -n "$input" && -e "$input" ]] || { echo "usage: $0 INPUT [--truth DIR] [--matcher M] [--out DIR]" >&2; exit 2; }
command -v colmap >/dev/null || { echo "colmap not installed: FMV3D_WITH_COLMAP=1 scripts/install-deps.sh" >&2; exit 1; }
[[ -x "$FMV3D" ]] || { echo "$FMV3D not built: make build" >&2; exit 1; }
out=${out:-$(mktemp -d /tmp/compare-colmap.XXXX)}
mkdir -p "$out"
log() { echo "[compare] $*" >&2; }
now() { date +%s.%N; }
# cpu KEY CMD...: runs CMD, adding its user + system CPU seconds to C[KEY] (fair under load, unlike wall time).
declare -A C
cpu() {
  local key=$1; shift
  local f; f=$(mktemp); local rc=0
  /usr/bin/time -o "$f" -f "%U %S" "$@" || rc=$?
  C[$key]=$(python3 -c "a,b=open('$f').read().split()[-2:];print(f'{${C[$key]:-0}+float(a)+float(b):.1f}')")
  rm -f "$f"; return $rc
}
elapsed() { python3 -c "print(f'{$2 - $1:.1f}')"; }

# --- fmv3d ---------------------------------------------------------------------------------------------------
ws=$out/fmv3d; rm -rf "$ws"
declare -A T
t0=$(now); "$FMV3D" -q frames "$input" -o "$ws"; t1=$(now); T[f_frames]=$(elapsed $t0 $t1)
cpu f_features "$FMV3D" -q features "$ws"; t2=$(now); T[f_features]=$(elapsed $t1 $t2)
cpu f_match "$FMV3D" -q match "$ws" --pairs "$matcher"; t3=$(now); T[f_match]=$(elapsed $t2 $t3)
cpu f_sparse "$FMV3D" -q sparse "$ws"; t4=$(now); T[f_sparse]=$(elapsed $t3 $t4)
T[f_total]=$(elapsed $t1 $t4)

# --- COLMAP on the very same frames (ours, so names and pixels match) -------------------------------------------
cw=$out/colmap; rm -rf "$cw"; mkdir -p "$cw/sparse" "$cw/txt"
cm=$matcher
if [[ $cm == auto ]]; then
  n=$(find "$ws/frames" -maxdepth 1 -type f ! -name '*.json' | wc -l)
  if (( n <= 50 )); then cm=exhaustive; else cm=sequential; fi
fi
t0=$(now)
cpu c_features colmap feature_extractor --database_path "$cw/db.db" --image_path "$ws/frames" --ImageReader.single_camera 1 \
  --ImageReader.camera_model OPENCV --SiftExtraction.use_gpu 0 >"$cw/extract.log" 2>&1
t1=$(now); T[c_features]=$(elapsed $t0 $t1)
cpu c_match colmap ${cm}_matcher --database_path "$cw/db.db" --SiftMatching.use_gpu 0 >"$cw/match.log" 2>&1
t2=$(now); T[c_match]=$(elapsed $t1 $t2)
cpu c_sparse colmap mapper --database_path "$cw/db.db" --image_path "$ws/frames" --output_path "$cw/sparse" >"$cw/map.log" 2>&1
t3=$(now); T[c_sparse]=$(elapsed $t2 $t3); T[c_total]=$(elapsed $t0 $t3)
# Largest COLMAP model (most images) to text.
best=""; best_n=-1
for m in "$cw"/sparse/*/; do
  colmap model_converter --input_path "$m" --output_path "$m" --output_type TXT >/dev/null 2>&1 || continue
  k=$(grep -vc '^#' "$m/images.txt" || true)
  if (( k > best_n )); then best=$m; best_n=$k; fi
done

summary() {  # model dir → "registered points reproj"
  "$FMV3D" -q model-info "$1" | awk '/^images:/{i=$2} /^points:/{p=$2} /^mean reprojection/{e=$4} END{print i, p, e}'
}
nframes=$(python3 -c "import json;print(len(json.load(open('$ws/frames/frames.json'))['frames']))")
read -r f_reg f_pts f_err <<<"$(summary "$ws/sparse")"
if [[ -n "$best" ]]; then read -r c_reg c_pts c_err <<<"$(summary "$best")"; else c_reg=0; c_pts=0; c_err=-; fi

printf '\n%-28s %14s %14s\n' "" "fmv3d" "COLMAP 3.8"
printf '%-28s %14s %14s\n' "features (s)" "${T[f_features]}" "${T[c_features]}"
printf '%-28s %14s %14s\n' "matching (s) [$cm]" "${T[f_match]}" "${T[c_match]}"
printf '%-28s %14s %14s\n' "mapping (s)" "${T[f_sparse]}" "${T[c_sparse]}"
printf '%-28s %14s %14s\n' "total (s, excl. frames)" "${T[f_total]}" "${T[c_total]}"
for k in features match sparse; do
  printf '%-28s %14s %14s\n' "$k (CPU s)" "${C[f_$k]}" "${C[c_$k]}"
done
printf '%-28s %14s %14s\n' "total (CPU s)" \
  "$(python3 -c "print(f'{${C[f_features]}+${C[f_match]}+${C[f_sparse]}:.1f}')")" \
  "$(python3 -c "print(f'{${C[c_features]}+${C[c_match]}+${C[c_sparse]}:.1f}')")"
printf '%-28s %14s %14s\n' "registered" "$f_reg/$nframes" "$c_reg/$nframes"
printf '%-28s %14s %14s\n' "points" "$f_pts" "$c_pts"
printf '%-28s %14s %14s\n' "mean reprojection (px)" "$f_err" "$c_err"
if [[ -n "$truth" ]]; then
  ev() {  # model dir, json copy → "centre% rotation° focal%"
    rm -f "$ws/report/sparse_eval.json"
    "$FMV3D" -q evaluate-sparse "$ws" --model "$1" --truth "$truth" >/dev/null 2>&1 || true
    if [[ -f "$ws/report/sparse_eval.json" ]]; then cp "$ws/report/sparse_eval.json" "$2"; else echo "{}" >"$2"; fi
    python3 -c "import json;d=json.load(open('$2'));g=lambda k:d.get(k,'-');print(g('centre_rmse_percent_of_extent'),g('median_relative_rotation_error_deg'),g('focal_relative_error_percent'))"
  }
  read -r f_c f_r f_f <<<"$(ev "$ws/sparse" "$out/fmv3d_eval.json")"
  if [[ -n "$best" ]]; then read -r c_c c_r c_f <<<"$(ev "$best" "$out/colmap_eval.json")"; else c_c=-; c_r=-; c_f=-; fi
  printf '%-28s %14s %14s\n' "centre RMSE (% extent)" "$f_c" "$c_c"
  printf '%-28s %14s %14s\n' "median rel. rotation (deg)" "$f_r" "$c_r"
  printf '%-28s %14s %14s\n' "focal error (%)" "$f_f" "$c_f"
fi
log "outputs in $out"
