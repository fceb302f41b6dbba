#!/bin/bash
# merge2.sh BIN NAME SEED DU,DV ALT_B: two 18-frame 960x540 town orbits (the default altitude, seed SEED; altitude
# ALT_B, seed SEED+100) as one 36-frame flight NAME (frames and truth merged; B's frames renamed flight-1NNNNN),
# then its workspace (frames/features/matches)
cd /work/runs/pp11
bin=$1; n=$2; s=$3; o=$4; alt=$5
c="synth --scene town --path orbit --frames 18 --size 960x540 --principal-offset $o --no-scene"
nice -n 5 $bin $c --seed $s -o ${n}A > $n.synth.log 2>&1
nice -n 5 $bin $c --seed $((s + 100)) --altitude $alt -o ${n}B >> $n.synth.log 2>&1
rm -rf $n; mkdir -p $n/frames $n/truth
cp ${n}A/frames/* $n/frames/
for f in ${n}B/frames/flight-0*; do b=$(basename $f); cp $f $n/frames/flight-1${b#flight-0}; done
python3 - ${n}A/truth ${n}B/truth $n/truth <<'PY'
import sys, shutil
a, b, out = sys.argv[1:4]
shutil.copy(a + '/cameras.txt', out + '/cameras.txt')
def imgs(d):
    L = [l for l in open(d + '/images.txt') if not l.startswith('#')]
    return [(L[i], L[i + 1]) for i in range(0, len(L) - 1, 2)]
A, B = imgs(a), imgs(b)
with open(out + '/images.txt', 'w') as f:
    for i, (h, p) in enumerate(A + B):
        t = h.split()
        t[0] = str(i + 1)
        if i >= len(A): t[9] = 'flight-1' + t[9][len('flight-0'):]
        f.write(' '.join(t) + '\n\n')
open(out + '/points3D.txt', 'w').close()
PY
nice -n 5 $bin frames $n/frames -o ${n}w > ${n}w.prep.log 2>&1 && nice -n 5 $bin features ${n}w >> ${n}w.prep.log 2>&1 && nice -n 5 $bin match ${n}w >> ${n}w.prep.log 2>&1
