#!/usr/bin/env bash
# `make fuzz`: runs every libFuzzer binary of FUZZ_BUILD/tests/fuzz for SECONDS each and prints executions and
# coverage per target.
#   tests/fuzz/run.sh FUZZ_BUILD FMV3D_CLI [SECONDS]
# Seed corpora are made in FUZZ_BUILD/fuzz/seeds/<target>/ (never committed): a small synthetic flight written by
# our own writers (`fmv3d synth` + `fmv3d reconstruct --fast`), real files from ../shared/data when present, the
# committed tests/fuzz/seeds/<target>/ and tests/fuzz/regressions/<target>/. New corpus units go to
# FUZZ_BUILD/fuzz/corpus/<target>/, crashing inputs to FUZZ_BUILD/fuzz/artifacts/<target>/.
# The targets' own stdout (library warnings) is discarded; sanitizer reports go to stderr, in the log.
# FUZZ_TARGETS="a b" limits the run to those targets; FUZZ_PARALLEL=N runs N targets at once (default 1).
set -uo pipefail
B=${1:?usage: run.sh FUZZ_BUILD FMV3D_CLI [SECONDS]}
CLI=${2:?usage: run.sh FUZZ_BUILD FMV3D_CLI [SECONDS]}
SECONDS_EACH=${3:-300}
SRC=$(cd "$(dirname "$0")" && pwd)
DATA=$(cd "$SRC/../../.." 2>/dev/null && pwd)/shared/data
W=$B/fuzz
mkdir -p "$W/seeds" "$W/corpus" "$W/artifacts" "$W/logs"
SPLIT='%%fmv3d-fuzz-next-file%%'

# --- seeds from our own writers: one small flight with KLV telemetry, reconstructed end to end ---------------
FLIGHT=$W/flight
if [[ ! -f "$FLIGHT/done" ]]; then
  rm -rf "$FLIGHT"
  echo "fuzz: writing a seed flight with $CLI (synth + reconstruct --fast) into $FLIGHT"
  if "$CLI" -q synth --scene building --path orbit --frames 60 --fps 6 --size 320x180 --klv -o "$FLIGHT/synth" &&
    "$CLI" -q reconstruct "$FLIGHT/synth/flight.ts" -o "$FLIGHT/ws" --fast --no-report; then
    touch "$FLIGHT/done"
  else
    echo "fuzz: the seed flight did not finish; seeding with what was written"
  fi
fi

seed() {  # seed TARGET FILE...: copies the existing files into the target's seed folder
  local t=$1; shift
  mkdir -p "$W/seeds/$t"
  for f in "$@"; do [[ -f "$f" ]] && cp "$f" "$W/seeds/$t/$(echo "${f#"$W"/}" | tr '/ ' '__')"; done
  return 0
}
joined() {  # joined TARGET NAME FILE...: one seed of the files joined by the split line (multi-file readers)
  local t=$1 name=$2; shift 2
  mkdir -p "$W/seeds/$t"
  local out=$W/seeds/$t/$name first=1
  : > "$out"
  for f in "$@"; do
    [[ $first == 1 ]] || echo "$SPLIT" >> "$out"
    first=0
    [[ -f "$f" ]] && sed 's/^mtllib .*/mtllib in.mtl/' "$f" >> "$out"
  done
}
WS=$FLIGHT/ws
seed ply_fuzz "$WS"/sparse/*.ply "$WS/dense/fused.ply" "$WS/mesh/poisson.ply"
seed features_fuzz $(ls "$WS"/features/*.feat 2>/dev/null | head -3) "$WS/matches/matches.bin" \
  $(ls "$WS"/dense/*.dmap "$WS"/dense/*/*.dmap 2>/dev/null | head -2)
seed json_fuzz "$WS/frames/frames.json" "$WS/project.json" "$WS/geo/georef.json" "$WS/frames/telemetry.json" \
  "$SRC/../../data/sensors.json"
joined colmap_fuzz truth "$FLIGHT/synth/truth/cameras.txt" "$FLIGHT/synth/truth/images.txt" \
  "$FLIGHT/synth/truth/points3D.txt"
joined colmap_fuzz sparse "$WS/sparse/cameras.txt" "$WS/sparse/images.txt" "$WS/sparse/points3D.txt"
joined obj_fuzz scene "$FLIGHT/synth/scene.obj" "$FLIGHT/synth/scene.mtl"
for obj in "$WS"/mesh/*.obj; do [[ -f "$obj" ]] && joined obj_fuzz "$(basename "$obj" .obj)" "$obj" "${obj%.obj}.mtl"; done
# KLV: the data stream of our own TS and of the real ones, cut into 4 KiB pieces at a few offsets.
klv_seed() {
  local ts=$1 name=$2
  [[ -f "$ts" ]] || return 0
  mkdir -p "$W/seeds/klv_fuzz"
  ffmpeg -v error -y -i "$ts" -map 0:d -c copy -f data "$W/$name.klv" 2>/dev/null || return 0
  for k in 0 1 2 3; do
    dd if="$W/$name.klv" of="$W/seeds/klv_fuzz/$name-$k" bs=1 skip=$((k * 4096)) count=4096 status=none
  done
}
klv_seed "$FLIGHT/synth/flight.ts" synth

# --- real files from ../shared/data (absent on a user's machine) ----------------------------------------------
if [[ -d "$DATA" ]]; then
  seed ply_fuzz "$DATA"/fmv/kwiver/aphill_pipeline_data/*.ply
  seed json_fuzz "$DATA/fmv/kwiver/klv_gold.json"
  for ts in "$DATA"/fmv/kwiver/videos/*.ts; do klv_seed "$ts" "$(basename "$ts" .ts)"; done
  seed exif_fuzz $(ls "$DATA"/photos/exif-gps/*.jpg 2>/dev/null | head -3)
  seed gpmf_fuzz $(ls "$DATA"/fmv/gopro/* 2>/dev/null | grep -vi -e readme -e '\.mp4$')
fi

# --- run -----------------------------------------------------------------------------------------------------
targets=()
for bin in "$B"/tests/fuzz/*_fuzz; do
  [[ -x "$bin" ]] || continue
  t=$(basename "$bin")
  if [[ -n "${FUZZ_TARGETS:-}" && " $FUZZ_TARGETS " != *" $t "* ]]; then continue; fi
  targets+=("$t")
done
[[ ${#targets[@]} -gt 0 ]] || { echo "fuzz: no targets built in $B/tests/fuzz"; exit 1; }

run_one() {
  local t=$1
  mkdir -p "$W/corpus/$t" "$W/seeds/$t" "$W/artifacts/$t"
  local dirs=("$W/corpus/$t" "$W/seeds/$t")
  [[ -d "$SRC/seeds/$t" ]] && dirs+=("$SRC/seeds/$t")
  [[ -d "$SRC/regressions/$t" ]] && dirs+=("$SRC/regressions/$t")
  # The scratch files of path-based readers go to a private tmp folder per run.
  local tmp
  tmp=$(mktemp -d)
  TMPDIR=$tmp nice -n 10 "$B/tests/fuzz/$t" -max_total_time="$SECONDS_EACH" -max_len=65536 -timeout=20 \
    -rss_limit_mb=2048 -close_fd_mask=1 -print_final_stats=1 -artifact_prefix="$W/artifacts/$t/" "${dirs[@]}" \
    > "$W/logs/$t.log" 2>&1
  echo $? > "$W/logs/$t.rc"
  rm -rf "$tmp"
}
echo "fuzz: ${#targets[@]} targets x ${SECONDS_EACH} s (${FUZZ_PARALLEL:-1} at a time): ${targets[*]}"
running=0
for t in "${targets[@]}"; do
  run_one "$t" &
  running=$((running + 1))
  if [[ $running -ge ${FUZZ_PARALLEL:-1} ]]; then wait -n; running=$((running - 1)); fi
done
wait

# --- report ----------------------------------------------------------------------------------------------------
failed=0
printf '%-22s %12s %8s %8s %8s %s\n' target executions exec/s cov ft result
for t in "${targets[@]}"; do
  log=$W/logs/$t.log
  execs=$(awk '/^stat::number_of_executed_units:/ {v = $2} END {print v}' "$log")
  rate=$(awk '/^stat::average_exec_per_sec:/ {v = $2} END {print v}' "$log")
  cov=$(grep -o 'cov: [0-9]*' "$log" | tail -1 | awk '{print $2}')
  ft=$(grep -o 'ft: [0-9]*' "$log" | tail -1 | awk '{print $2}')
  rc=$(cat "$W/logs/$t.rc" 2>/dev/null || echo 1)
  result=clean
  if [[ $rc != 0 ]]; then
    result="FAILED (exit $rc): see $log and $W/artifacts/$t/"
    failed=1
  fi
  printf '%-22s %12s %8s %8s %8s %s\n' "$t" "${execs:-?}" "${rate:-?}" "${cov:-?}" "${ft:-?}" "$result"
done
exit $failed
