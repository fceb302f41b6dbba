#!/usr/bin/env bash
# Plots a bench/rss_sample.sh timeline (seconds, RSS MiB, label) to a PNG, one colour per label (stage).
#   bench/plot_rss.sh RSS_TSV OUT_PNG [TITLE]
set -euo pipefail
TSV=$1 PNG=$2 TITLE=${3:-}
labels=$(awk -F'\t' 'NR > 1 && !seen[$3]++ { print $3 }' "$TSV")
plots=""
for l in $labels; do
  plots+="${plots:+, }'$TSV' using (strcol(3) eq '$l' ? \$1 : NaN):2 with lines lw 2 title '$l'"
done
gnuplot <<GP
set terminal pngcairo size 1100,500 noenhanced
set output '$PNG'
set datafile separator '\t'
set key autotitle columnhead outside right
set title '$TITLE'
set xlabel 'seconds'
set ylabel 'resident memory (MiB)'
set grid
plot $plots
GP
