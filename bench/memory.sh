#!/usr/bin/env bash
# Peak resident memory of `fmv3d reconstruct`, stage by stage: each stage is run alone in its own process
# (`--from S --until S` on a workspace whose earlier stages are done) under /usr/bin/time, so each figure is that
# stage's own peak (GNU time's "Maximum resident set size").
#   bench/memory.sh FMV3D INPUT OUT_DIR [reconstruct options...]
# Prints one line per stage: stage, peak RSS (MiB), wall seconds; writes OUT_DIR/memory.tsv.
set -euo pipefail
CLI=$1 INPUT=$2 OUT=$3
shift 3
WS=$OUT/ws
mkdir -p "$OUT"
stages=(frames features match sparse georef dense mesh texture dsm ortho)
printf 'stage\tpeak_rss_mib\twall_s\n' > "$OUT/memory.tsv"
for s in "${stages[@]}"; do
  /usr/bin/time -f '%M %e' -o "$OUT/time-$s.txt" \
    "$CLI" -q reconstruct "$INPUT" -o "$WS" --from "$s" --until "$s" --no-report "$@"
  read -r kb wall < "$OUT/time-$s.txt"
  printf '%s\t%d\t%s\n' "$s" $((kb / 1024)) "$wall" | tee -a "$OUT/memory.tsv"
done
