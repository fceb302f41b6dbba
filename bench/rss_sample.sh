#!/usr/bin/env bash
# Resident memory of a command over time: runs it under GNU time and samples its VmRSS every second.
#   bench/rss_sample.sh OUT_PREFIX LABEL CMD...
# Appends "seconds<TAB>rss_mib<TAB>label" lines to OUT_PREFIX.rss.tsv (seconds since the file's first sample,
# so consecutive commands form one timeline) and GNU time's report to OUT_PREFIX.LABEL.time; exits with CMD's status.
set -uo pipefail
OUT=$1 LABEL=$2
shift 2
TSV=$OUT.rss.tsv
[ -s "$TSV" ] || printf 'seconds\trss_mib\tlabel\tt0\n' > "$TSV"
start=$(awk -F'\t' 'NR == 2 { print $4; exit }' "$TSV")  # wall clock of the first sample, when present
/usr/bin/time -v -o "$OUT.$LABEL.time" "$@" &
tpid=$!
sleep 0.2
pid=$(pgrep -P "$tpid" | head -1)
t0=${start:-$(date +%s.%N)}
while kill -0 "$tpid" 2> /dev/null; do
  if [ -n "$pid" ] && [ -r "/proc/$pid/status" ]; then
    kb=$(awk '/^VmRSS:/ { print $2 }' "/proc/$pid/status" 2> /dev/null)
    now=$(date +%s.%N)
    [ -n "$kb" ] && printf '%.1f\t%.1f\t%s\t%s\n' "$(echo "$now - $t0" | bc)" "$(echo "$kb / 1024" | bc -l)" "$LABEL" "$t0" >> "$TSV"
  fi
  sleep 1
done
wait "$tpid"
