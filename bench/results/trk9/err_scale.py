#!/usr/bin/env python3
"""err_scale.py WS: reprojection error of every observation of WS/sparse against its keypoint's SIFT scale."""
import sys, os, json, struct, math
from array import array
import statistics
class np:
    pass
ws = sys.argv[1]
cams = {}
for l in open(f'{ws}/sparse/cameras.txt'):
    if l.startswith('#'): continue
    t = l.split(); cams[int(t[0])] = (t[1], [float(x) for x in t[4:]])
pts = {}
for l in open(f'{ws}/sparse/points3D.txt'):
    if l.startswith('#'): continue
    t = l.split(); pts[int(t[0])] = [float(x) for x in t[1:4]]
def scales_of(name):
    stem = os.path.splitext(name)[0]
    b = open(os.path.join(ws, 'features', stem + '.feat'), 'rb').read()
    ver, w, h, n, L = struct.unpack_from('<IiiII', b, 8)
    off = 8 + 20 + L + (8 if ver >= 2 else 0)
    kp = array('f'); kp.frombytes(b[off:off + 16 * n]); return list(kp[2::4])
def q2r(w, x, y, z):
    return [[1-2*(y*y+z*z), 2*(x*y-z*w), 2*(x*z+y*w)], [2*(x*y+z*w), 1-2*(x*x+z*z), 2*(y*z-x*w)], [2*(x*z-y*w), 2*(y*z+x*w), 1-2*(x*x+y*y)]]
lines = [l for l in open(f'{ws}/sparse/images.txt') if not l.startswith('#')]
E, S = [], []
for a, b in zip(lines[0::2], lines[1::2]):
    t = a.split(); R = q2r(*map(float, t[1:5])); T = list(map(float, t[5:8])); cam = cams[int(t[8])]; sc = scales_of(t[9])
    fx, fy, cx, cy, k1, k2, p1, p2 = (cam[1] + [0]*8)[:8]
    u = b.split(); k = 0
    for i in range(0, len(u), 3):
        pid = int(u[i+2])
        if pid >= 0:
            P = pts[pid]; X = [sum(R[r][c]*P[c] for c in range(3)) + T[r] for r in range(3)]; x, y = X[0]/X[2], X[1]/X[2]; r2 = x*x+y*y; d = 1+k1*r2+k2*r2*r2
            xd = x*d + 2*p1*x*y + p2*(r2+2*x*x); yd = y*d + p1*(r2+2*y*y) + 2*p2*x*y
            E.append(math.hypot(fx*xd+cx-float(u[i]), fy*yd+cy-float(u[i+1]))); S.append(sc[i//3])
def q(v, p):
    v = sorted(v); return v[min(len(v)-1, int(p*len(v)))]
Ss = sorted(S)
print(f'{len(E)} obs, median err {q(E,.5):.3f}, mean {sum(E)/len(E):.3f}; scale quantiles', [round(q(S,p),2) for p in (.25,.5,.75,.9)])
for lo, hi in [(0,1.5),(1.5,2.5),(2.5,4),(4,8),(8,16),(16,1e9)]:
    e = [x for x, s_ in zip(E, S) if lo <= s_ < hi]; r = [x/s_ for x, s_ in zip(E, S) if lo <= s_ < hi]
    if e: print(f' scale [{lo},{hi}): n {len(e):6d} median err {q(e,.5):.3f}  err/scale median {q(r,.5):.3f}  p99.7 {q(e,.997):.2f}')
