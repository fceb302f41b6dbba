#!/bin/bash
# GCP georeference against a synthetic flight's truth, over click-noise seeds (bench/results/hand7.md).
#   bench/gcp_sweep.sh SYNTH WS "NOISE" SEEDS [FIRST] [MODE] [-- EXTRA truth-projections options]
# SYNTH: an `fmv3d synth` folder; WS: its workspace after `sparse` (or, for the exact-camera floor, a workspace
# whose sparse/ is SYNTH/truth); NOISE: "--noise 1" (Gaussian σ px) or "--noise-max 1" (uniform ±px); MODE:
# "both" (default: --gcp-no-adjust, then adjusted) or "similarity". 6 points (5 control + 1 check) clicked in every
# frame that sees them, coordinates in WGS84 UTM 32N around the truth's origin. Prints per seed the worst camera
# centre error in % of the extent (largest distance between two true centres), the camera RMS (m) and the check
# point's residual. FMV3D: the binary (default build/fmv3d; use a copy if you rebuild meanwhile).
set -euo pipefail
F=${FMV3D:-build/fmv3d}
synth=$1 ws=$2 noise=$3 seeds=$4 first=${5:-1} mode=${6:-both}
shift $(($# < 6 ? $# : 6))
[ "${1:-}" = "--" ] && shift
here=$(cd "$(dirname "$0")" && pwd)
gcp=$(mktemp --suffix=.txt)
trap 'rm -f "$gcp"' EXIT
origin=46.95,7.44,540
for seed in $(seq "$first" "$seeds"); do
  # shellcheck disable=SC2086
  "$F" truth-projections "$synth" --ws "$ws" --points 6 --check 1 $noise --seed "$seed" --format gcp \
    --crs 'WGS84 UTM 32N' --origin $origin "$@" -o "$gcp" 2>/dev/null
  "$F" -q georef "$ws" --gcp "$gcp" --origin $origin --gcp-no-adjust >/dev/null
  line="seed $seed | similarity: $(python3 "$here/gcp_centres.py" "$ws" "$synth")"
  if [ "$mode" = both ]; then
    "$F" -q georef "$ws" --gcp "$gcp" --origin $origin >/dev/null
    line="$line | adjusted: $(python3 "$here/gcp_centres.py" "$ws" "$synth")"
  fi
  echo "$noise | $line"
done
