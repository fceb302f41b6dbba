#!/usr/bin/env python3
"""truth_check.py WS BASE_WS TRUTH_DIR: every observation of WS/sparse against the true cameras (pinhole truth).
Each point is triangulated from its BASE_WS observations (same point id) with the true cameras; observations in WS
but not in BASE_WS are the added ones. Prints the truth-error distribution of both kinds."""
import sys, os, struct, math
from array import array
ws, base, truth = sys.argv[1:4]
LOO = len(sys.argv) > 4
def q2r(w, x, y, z):
    return [[1-2*(y*y+z*z), 2*(x*y-z*w), 2*(x*z+y*w)], [2*(x*y+z*w), 1-2*(x*x+z*z), 2*(y*z-x*w)], [2*(x*z-y*w), 2*(y*z+x*w), 1-2*(x*x+y*y)]]
def images(d):
    L = [l for l in open(f'{d}/images.txt') if not l.startswith('#')]
    out = {}
    for a in L[0::2]:
        t = a.split(); out[int(t[0])] = (t[9], q2r(*map(float, t[1:5])), list(map(float, t[5:8])))
    return out
def tracks(d):
    out = {}
    for l in open(f'{d}/points3D.txt'):
        if l.startswith('#'): continue
        t = l.split(); tr = list(map(int, t[8:])); out[int(t[0])] = set(zip(tr[0::2], tr[1::2]))
    return out
c = [l.split() for l in open(f'{truth}/cameras.txt') if not l.startswith('#')][0]
fx, fy, cx, cy = map(float, c[4:8])
tim = {v[0]: v for v in images(truth).values()}
mc = [l.split() for l in open(f'{ws}/sparse/cameras.txt') if not l.startswith('#')][0]
mp = list(map(float, mc[4:])) + [0.0] * 8
mpts = {}
for l in open(f'{ws}/sparse/points3D.txt'):
    if l.startswith('#'): continue
    t = l.split(); mpts[int(t[0])] = list(map(float, t[1:4]))
def model_err(iid, k, X):
    _, R, t = mim[iid]; name, *_r, px, py, s = obs(iid, k)
    Xc = [sum(R[r][j] * X[j] for j in range(3)) + t[r] for r in range(3)]
    x, y = Xc[0] / Xc[2], Xc[1] / Xc[2]; r2 = x * x + y * y; f = mp
    d = 1 + f[4] * r2 + f[5] * r2 * r2
    xd = x * d + 2 * f[6] * x * y + f[7] * (r2 + 2 * x * x); yd = y * d + f[6] * (r2 + 2 * y * y) + 2 * f[7] * x * y
    return math.hypot(f[0] * xd + f[2] - px, f[1] * yd + f[3] - py)
pairs = []
opairs = []
mim = images(f'{ws}/sparse')
kps = {}
def kp(name):
    if name not in kps:
        b = open(os.path.join(ws, 'features', os.path.splitext(name)[0] + '.feat'), 'rb').read()
        ver, w, h, n, L = struct.unpack_from('<IiiII', b, 8)
        off = 8 + 20 + L + (8 if ver >= 2 else 0)
        a = array('f'); a.frombytes(b[off:off + 16 * n]); kps[name] = (a[0::4], a[1::4], a[2::4])
    return kps[name]
def solve3(A, b):
    import copy
    M = [A[i][:] + [b[i]] for i in range(3)]
    for i in range(3):
        p = max(range(i, 3), key=lambda r: abs(M[r][i])); M[i], M[p] = M[p], M[i]
        if abs(M[i][i]) < 1e-15: return None
        for r in range(3):
            if r != i:
                f = M[r][i] / M[i][i]; M[r] = [x - f * y for x, y in zip(M[r], M[i])]
    return [M[i][3] / M[i][i] for i in range(3)]
def obs(iid, k):
    name = mim[iid][0]; x, y, s = kp(name)
    return name, (x[k] - cx) / fx, (y[k] - cy) / fy, x[k], y[k], s[k]
wt, bt = tracks(f'{ws}/sparse'), tracks(f'{base}/sparse')
orig_e, add_e = [], []
for pid, tr in wt.items():
    if pid not in bt: continue
    base_obs = bt[pid] & tr
    def tri(obs_set):
     A = [[0.0]*3 for _ in range(3)]; b = [0.0]*3
     for (iid, k) in obs_set:
        name, u, v, *_ = obs(iid, k); _, R, t = tim[name]
        for row, val in ((0, u), (1, v)):
            a = [val * R[2][j] - R[row][j] for j in range(3)]; r = t[row] - val * t[2]
            for i in range(3):
                b[i] += a[i] * r
                for j in range(3): A[i][j] += a[i] * a[j]
     return solve3(A, b)
    X0 = tri(base_obs)
    if X0 is None: continue
    for (iid, k) in tr:
        X = X0
        if LOO and (iid, k) in bt[pid]:
            if len(base_obs) < 3: continue
            X = tri(base_obs - {(iid, k)})
            if X is None: continue
        name, u, v, px, py, s = obs(iid, k); _, R, t = tim[name]
        Xc = [sum(R[r][j] * X[j] for j in range(3)) + t[r] for r in range(3)]
        if Xc[2] <= 0: continue
        e = math.hypot(fx * Xc[0] / Xc[2] + cx - px, fy * Xc[1] / Xc[2] + cy - py)
        (orig_e if (iid, k) in bt[pid] else add_e).append(e)
        if (iid, k) not in bt[pid]: pairs.append((model_err(iid, k, mpts[pid]), e, s))
        elif len(opairs) < 400000: opairs.append((model_err(iid, k, mpts[pid]), e, s))
def summ(n, e):
    e = sorted(e)
    if not e: print(n, 'none'); return
    q = lambda p: e[min(len(e) - 1, int(p * len(e)))]
    print(f'{n}: {len(e)} obs, truth error median {q(.5):.3f} p90 {q(.9):.3f} p99 {q(.99):.3f}; > 1 px {sum(x > 1 for x in e)}, > 2 px {sum(x > 2 for x in e)}, > 4 px {sum(x > 4 for x in e)}')
summ('original', orig_e); summ('added', add_e)

for nm, pairs in (('original', opairs), ('added', pairs)):
 print(nm, 'by final model residual: bin, n, truth median, share truth > 1 px, scale median')
 for lo, hi in [(0, .3), (.3, .6), (.6, 1), (1, 1.5), (1.5, 2.5), (2.5, 9)]:
  b = [p for p in pairs if lo <= p[0] < hi]
  if b:
        te = sorted(p[1] for p in b); sc = sorted(p[2] for p in b)
        print(f'  [{lo},{hi}) n {len(b)} truth median {te[len(te)//2]:.3f} >1px {sum(x > 1 for x in te)/len(te):.2f} scale {sc[len(sc)//2]:.2f}')
