#!/usr/bin/env bash
# Georeference side by side: COLMAP 3.8's model_aligner and `fmv3d georef` on the same sparse model.
#
#   bench/compare_colmap_georef.sh WS SYNTH [--out DIR]
#
# WS is an fmv3d workspace after `georef` (frames/frames.json with telemetry, sparse/, geo/georef.json); SYNTH is
# the `fmv3d synth --klv` folder it came from. COLMAP gets what its aligner can use: the registered keyframes'
# telemetry positions, in the same local ENU frame as ours (georef.json's origin), with its robust alignment
# (RANSAC, max error 3·σ of the GPS = 9 m). Its aligned model is then scored by the same `fmv3d evaluate-geo`.
# Prints the absolute error over the true surface (RMS, horizontal, vertical) for both.
set -euo pipefail

here=$(cd "$(dirname "$0")/.." && pwd)
FMV3D=${FMV3D:-$here/build/fmv3d}
ws=""; synth=""; out=""
while [[ $# -gt 0 ]]; do
  case "$1" in
    --out) out=$2; shift 2 ;;
    -h|--help) sed -n '2,10p' "$0"; exit 0 ;;
    *) if [[ -z "$ws" ]]; then ws=$1; else synth=$1; fi; shift ;;
  esac
done
[[ -d "$ws/geo" && -f "$synth/truth.json" ]] || { echo "usage: $0 WS SYNTH [--out DIR] (WS after georef)" >&2; exit 2; }
command -v colmap >/dev/null || { echo "colmap not installed: FMV3D_WITH_COLMAP=1 scripts/install-deps.sh" >&2; exit 1; }
out=${out:-$(mktemp -d /tmp/compare-georef.XXXX)}
mkdir -p "$out/ws/geo" "$out/aligned"

# Keyframe positions in georef.json's ENU frame (WGS84 → ECEF → ENU; heights as the fit used them).
python3 - "$ws" "$out/ref.txt" <<'PY'
import json, math, sys
ws, ref = sys.argv[1], sys.argv[2]
g = json.load(open(ws + "/geo/georef.json"))
o = g["origin"]
hae = g["vertical_datum"].startswith("WGS84")
a, f = 6378137.0, 1 / 298.257223563
e2 = f * (2 - f)
def ecef(lat, lon, h):
    sl, cl = math.sin(math.radians(lat)), math.cos(math.radians(lat))
    n = a / math.sqrt(1 - e2 * sl * sl)
    return [(n + h) * cl * math.cos(math.radians(lon)), (n + h) * cl * math.sin(math.radians(lon)), (n * (1 - e2) + h) * sl]
la, lo = math.radians(o["lat"]), math.radians(o["lon"])
rows = [[-math.sin(lo), math.cos(lo), 0],
        [-math.sin(la) * math.cos(lo), -math.sin(la) * math.sin(lo), math.cos(la)],
        [math.cos(la) * math.cos(lo), math.cos(la) * math.sin(lo), math.sin(la)]]
x0 = ecef(o["lat"], o["lon"], o["alt"])
registered = set()
for line in open(ws + "/sparse/images.txt"):
    p = line.split()
    if len(p) >= 10 and not line.startswith("#") and p[0].isdigit() and len(p) == 10:
        registered.add(p[9])
n = 0
with open(ref, "w") as out:
    for fr in json.load(open(ws + "/frames/frames.json"))["frames"]:
        t = fr.get("telemetry") or {}
        h = t.get("sensor_altitude_hae" if hae else "sensor_altitude_msl")
        if fr["name"] not in registered or "sensor_latitude" not in t or h is None:
            continue
        d = [u - v for u, v in zip(ecef(t["sensor_latitude"], t["sensor_longitude"], h), x0)]
        e = [sum(r[i] * d[i] for i in range(3)) for r in rows]
        out.write("%s %.4f %.4f %.4f\n" % (fr["name"], e[0], e[1], e[2]))
        n += 1
print("[compare] %d registered keyframes with telemetry positions" % n, file=sys.stderr)
PY

t0=$(date +%s.%N)
colmap model_aligner --input_path "$ws/sparse" --output_path "$out/aligned" --ref_images_path "$out/ref.txt" \
  --ref_is_gps 0 --alignment_type custom --robust_alignment 1 --robust_alignment_max_error 9 > "$out/colmap.log" 2>&1
t1=$(date +%s.%N)
colmap model_converter --input_path "$out/aligned" --output_path "$out/aligned" --output_type TXT >> "$out/colmap.log" 2>&1
cp -r "$ws/frames" "$out/ws/"
cp "$ws/geo/georef.json" "$out/ws/geo/"
rm -rf "$out/ws/geo/sparse_enu" && cp -r "$out/aligned" "$out/ws/geo/sparse_enu"
"$FMV3D" -q evaluate-geo "$out/ws" --truth "$synth" > "$out/colmap_eval.json"
"$FMV3D" -q evaluate-geo "$ws" --truth "$synth" > "$out/fmv3d_eval.json"
python3 - "$out" "$(echo "$t1 - $t0" | bc)" <<'PY'
import json, sys
out, secs = sys.argv[1], float(sys.argv[2])
for who in ("fmv3d", "colmap"):
    s = json.load(open("%s/%s_eval.json" % (out, who)))["surface"]
    print("%-7s surface RMS %.3f m (horizontal %.3f, vertical %.3f), rotation %.3f°, scale %+.4f%s" % (
        who, s["rms_m"], s["horizontal_rms_m"], s["vertical_rms_m"], s["rotation_error_deg"], s["scale_error"],
        "" if who == "fmv3d" else ", model_aligner %.1f s" % secs))
PY
