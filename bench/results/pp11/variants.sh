#!/bin/bash
# variants.sh BIN: the seed-7 (12, -16) orbit with altitude swings 0/15/30/60/120 m, truth only (20,000 sampled
# surface points with depth-tested tracks), for the bound at the truth (crb truth V*/truth 0 SIGMA)
cd /work/runs/pp11
for s in 0 15 30 60 120; do
  nice -n 5 $1 synth --scene town --path orbit --frames 36 --size 960x540 --seed 7 --principal-offset 12,-16 --no-scene \
    --truth-points 20000 --altitude-swing $s -o V$s > V$s.synth.log 2>&1
done
