#!/usr/bin/env bash
# sparse_eval.sh BIN TEMPLATE_WS OUT TRUTH [sparse options]: copies the prepared workspace, runs sparse, evaluates.
set -euo pipefail
bin=$1; tpl=$2; out=$3; truth=$4; shift 4
rm -rf "$out"; mkdir -p "$out"; cp -r "$tpl/frames" "$tpl/features" "$tpl/matches" "$out/"
/usr/bin/time -o "$out/sparse_time.txt" -f "%U %S %e" nice -n 5 "$bin" -q sparse "$out" "$@"
"$bin" -q evaluate-sparse "$out" --truth "$truth" > /dev/null 2>&1 || true
python3 - "$out" <<'PY'
import json, sys, os
ws = sys.argv[1]
e = json.load(open(f'{ws}/report/sparse_eval.json'))
s = json.load(open(f'{ws}/report/sparse.json'))
t = open(f'{ws}/sparse_time.txt').read().split()
tr = s['mapper']['tracks']; g = s['mapper'].get('guided_completion', {})
if isinstance(g, list): g = {'observations_added': '+'.join(str(x['observations_added']) for x in g), 'descriptor_bound_squared': '/'.join(str(x['descriptor_bound_squared']) for x in g), 'conflicts': '/'.join(str(x['conflicts']) for x in g)}
sc = [f"{d.get('group')}:{'free' if d.get('freed') else 'held'}({d.get('delta_chi2', 0):.1f}/{d.get('delta_chi2_needed', 0):.1f})" for d in s.get('self_calibration', [])] if isinstance(s.get('self_calibration'), list) else s.get('self_calibration')
print(f"{ws}: pts {tr.get('model_points')} obs {tr.get('model_observations')} track {tr.get('model_mean_track_length', 0):.3f} "
      f"UF3 {tr.get('union_find_mean_length_3_or_more_views', 0):.3f} | centre {e.get('centre_rmse_percent_of_extent'):.4f}% "
      f"rot {e.get('median_relative_rotation_error_deg'):.4f} focal {e.get('focal_relative_error_percent'):.4f}% "
      f"fx {e.get('focal_x_relative_error_percent', float('nan')):.4f}% pp {e.get('principal_point_error_px'):.2f}px "
      f"reproj {s.get('mean_reprojection_error_px'):.3f} | cpu {float(t[0])+float(t[1]):.1f}s wall {t[2]}s "
      f"| guided +{g.get('observations_added', '-')} bound {g.get('descriptor_bound_squared', '-')} conflicts {g.get('conflicts', '-')}")
print('  selfcal:', sc)
PY
