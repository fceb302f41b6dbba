#!/usr/bin/env bash
# Side-by-side: COLMAP 3.8 (Debian package, CPU) and fmv3d on the same images, same machine, same run.
#
#   bench/compare_colmap.sh INPUT [--truth DIR] [--matcher exhaustive|sequential] [--out DIR] [--colmap-from DIR]
#
# INPUT is a folder of images or a video file. --truth is a COLMAP text model of the true cameras (e.g. from
# `fmv3d synth` (DIR/truth) or `fmv3d import-truth strecha ...`), matched to our frames by image name.
# --colmap-from reuses the COLMAP half of an earlier run on the same frames (its OUT/colmap with times.txt),
# e.g. to compare two fmv3d builds against one COLMAP run made in the same session.
# Prints time per stage, registered images, points, mean track length, mean reprojection error and (with
# --truth) pose, focal and principal-point error for both. COLMAP runs with `nice`; the CPU seconds are the fair
# speed figure on a shared machine.
# Needs `colmap` (FMV3D_WITH_COLMAP=1 scripts/install-deps.sh) and a built fmv3d (make build).
set -euo pipefail

here=$(cd "$(dirname "$0")/.." && pwd)
FMV3D=${FMV3D:-$here/build/fmv3d}
input=""; truth=""; matcher=auto; out=""; colmap_from=""
while [[ $# -gt 0 ]]; do
  case "$1" in
    --truth) truth=$2; shift 2 ;;
    --matcher) matcher=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --colmap-from) colmap_from=$2; shift 2 ;;
    -h|--help) sed -n '2,13p' "$0"; exit 0 ;;
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
cm=$matcher
if [[ $cm == auto ]]; then
  n=$(find "$ws/frames" -maxdepth 1 -type f ! -name '*.json' | wc -l)
  if (( n <= 50 )); then cm=exhaustive; else cm=sequential; fi
fi
# stage KEY CMD...: runs CMD under nice, appending "KEY wall_s cpu_s" to $cw/times.txt.
stage() {
  local key=$1; shift
  local t0; t0=$(now)
  cpu "c_$key" nice -n 10 "$@" >"$cw/$key.log" 2>&1
  echo "$key $(elapsed "$t0" "$(now)") ${C[c_$key]}" >>"$cw/times.txt"
}
if [[ -n "$colmap_from" ]]; then
  cw=$colmap_from
  [[ -f "$cw/times.txt" ]] || { echo "$cw/times.txt missing: not a finished COLMAP run" >&2; exit 1; }
  log "COLMAP: reusing $cw"
else
  cw=$out/colmap; rm -rf "$cw"; mkdir -p "$cw/sparse"
  stage features colmap feature_extractor --database_path "$cw/db.db" --image_path "$ws/frames" \
    --ImageReader.single_camera 1 --ImageReader.camera_model OPENCV --SiftExtraction.use_gpu 0
  stage match colmap ${cm}_matcher --database_path "$cw/db.db" --SiftMatching.use_gpu 0
  stage sparse colmap mapper --database_path "$cw/db.db" --image_path "$ws/frames" --output_path "$cw/sparse"
fi
while read -r key wall cpu_s; do T[c_$key]=$wall; C[c_$key]=$cpu_s; done <"$cw/times.txt"
T[c_total]=$(python3 -c "print(f'{${T[c_features]}+${T[c_match]}+${T[c_sparse]}:.1f}')")
# Largest COLMAP model (most images) to text.
best=""; best_n=-1
for m in "$cw"/sparse/*/; do
  colmap model_converter --input_path "$m" --output_path "$m" --output_type TXT >/dev/null 2>&1 || continue
  k=$(grep -vc '^#' "$m/images.txt" || true)
  if (( k > best_n )); then best=$m; best_n=$k; fi
done

summary() {  # model dir → "registered points reproj track_length principal_point"
  "$FMV3D" -q model-info "$1" | awk '/^images:/{i=$2} /^points:/{p=$2} /^mean reprojection/{e=$4}
    /^mean track length:/{t=$4} /^camera 1:/{match($0, /pp=\([^)]*\)/); pp=substr($0, RSTART+3, RLENGTH-3); gsub(/ /, "", pp)}
    END{print i, p, e, t, pp}'
}
nframes=$(python3 -c "import json;print(len(json.load(open('$ws/frames/frames.json'))['frames']))")
read -r f_reg f_pts f_err f_trk f_pp <<<"$(summary "$ws/sparse")"
if [[ -n "$best" ]]; then read -r c_reg c_pts c_err c_trk c_pp <<<"$(summary "$best")"; else c_reg=0; c_pts=0; c_err=-; c_trk=-; c_pp=-; fi

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
printf '%-28s %14s %14s\n' "mean track length" "$f_trk" "$c_trk"
printf '%-28s %14s %14s\n' "principal point (px)" "$f_pp" "$c_pp"
if [[ -n "$truth" ]]; then
  ev() {  # model dir, json copy → "centre% rotation° focal%"
    rm -f "$ws/report/sparse_eval.json"
    "$FMV3D" -q evaluate-sparse "$ws" --model "$1" --truth "$truth" >/dev/null 2>&1 || true
    if [[ -f "$ws/report/sparse_eval.json" ]]; then cp "$ws/report/sparse_eval.json" "$2"; else echo "{}" >"$2"; fi
    python3 -c "import json;d=json.load(open('$2'));g=lambda k:d.get(k,'-');print(g('centre_rmse_percent_of_extent'),g('median_relative_rotation_error_deg'),g('focal_relative_error_percent'),g('principal_point_error_px'))"
  }
  read -r f_c f_r f_f f_p <<<"$(ev "$ws/sparse" "$out/fmv3d_eval.json")"
  if [[ -n "$best" ]]; then read -r c_c c_r c_f c_p <<<"$(ev "$best" "$out/colmap_eval.json")"; else c_c=-; c_r=-; c_f=-; c_p=-; fi
  printf '%-28s %14s %14s\n' "centre RMSE (% extent)" "$f_c" "$c_c"
  printf '%-28s %14s %14s\n' "median rel. rotation (deg)" "$f_r" "$c_r"
  printf '%-28s %14s %14s\n' "focal error (%)" "$f_f" "$c_f"
  printf '%-28s %14s %14s\n' "principal point error (px)" "$f_p" "$c_p"
fi
log "outputs in $out"
