#!/usr/bin/env python3
# Worst camera-centre distance between WS/geo/sparse_enu and SYNTH/truth (same ENU frame: georef --origin = the
# truth's origin), as % of the extent (largest distance between two true centres); bench/gcp_sweep.sh.
# Prints "worst_pct rms_m check=<check_rms_m> n=<cameras> extent=<m>".
import math, sys, json
def centres(path):
    lines = [l for l in open(path) if l.strip() and not l.startswith('#')]
    out = {}
    for i in range(0, len(lines), 2):
        v = lines[i].split()
        w, x, y, z = map(float, v[1:5]); t = list(map(float, v[5:8]))
        R = [[1-2*(y*y+z*z), 2*(x*y-z*w), 2*(x*z+y*w)], [2*(x*y+z*w), 1-2*(x*x+z*z), 2*(y*z-x*w)], [2*(x*z-y*w), 2*(y*z+x*w), 1-2*(x*x+y*y)]]
        out[v[9]] = [-(R[0][c]*t[0]+R[1][c]*t[1]+R[2][c]*t[2]) for c in range(3)]
    return out
ws, synth = sys.argv[1], sys.argv[2]
est = centres(f'{ws}/geo/sparse_enu/images.txt'); tru = centres(f'{synth}/truth/images.txt')
ext = max(math.dist(a, b) for a in tru.values() for b in tru.values())
errs = [math.dist(c, tru[n]) for n, c in est.items()]
g = json.load(open(f'{ws}/geo/georef.json'))
print(f"{100*max(errs)/ext:.4f} {math.sqrt(sum(e*e for e in errs)/len(errs)):.3f} check={g['gcps'].get('check_rms_m')} n={len(errs)} extent={ext:.1f}")
