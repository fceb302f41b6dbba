#!/usr/bin/env bash
# Peak resident memory of `fmv3d reconstruct`, stage by stage: each stage is run alone in its own process
# (`--from S --until S` on a workspace whose earlier stages are done) under /usr/bin/time -v, so each figure is
# that stage's own peak (GNU time's "Maximum resident set size"); VmRSS is also sampled every second
# (bench/rss_sample.sh) and, when gnuplot is installed, plotted over the whole run to OUT_DIR/memory.png.
#   bench/memory.sh FMV3D INPUT OUT_DIR [reconstruct options...]
#   STAGES="frames features" bench/memory.sh ...    only those stages (default: all of them)
# Prints one line per stage: stage, peak RSS (MiB), wall seconds; writes OUT_DIR/memory.tsv.
set -euo pipefail
CLI=$1 INPUT=$2 OUT=$3
shift 3
HERE=$(cd "$(dirname "$0")" && pwd)
WS=$OUT/ws
mkdir -p "$OUT"
read -r -a stages <<< "${STAGES:-frames features match sparse georef dense mesh texture tiles dsm ortho}"
printf 'stage\tpeak_rss_mib\twall_s\n' > "$OUT/memory.tsv"
rm -f "$OUT/run.rss.tsv"
for s in "${stages[@]}"; do
  "$HERE/rss_sample.sh" "$OUT/run" "$s" \
    "$CLI" -q reconstruct "$INPUT" -o "$WS" --from "$s" --until "$s" --no-report "$@"
  kb=$(awk -F': ' '/Maximum resident set size/ { print $2 }' "$OUT/run.$s.time")
  wall=$(awk -F': ' '/Elapsed \(wall clock\)/ { print $2 }' "$OUT/run.$s.time")
  printf '%s\t%d\t%s\n' "$s" $((kb / 1024)) "$wall" | tee -a "$OUT/memory.tsv"
done
if command -v gnuplot > /dev/null; then
  "$HERE/plot_rss.sh" "$OUT/run.rss.tsv" "$OUT/memory.png" "$(basename "$INPUT") $*"
fi
