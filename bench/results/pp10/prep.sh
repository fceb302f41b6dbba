#!/bin/bash
# prep.sh NAME SEED DU,DV : synth a 36-frame 960x540 town orbit and make its workspace (frames/features/matches) with main's binary
cd /work/runs/pp10
n=$1; s=$2; o=$3
nice -n 5 ./fmv3d-base synth --scene town --path orbit --frames 36 --size 960x540 --seed $s --principal-offset $o --no-scene -o $n > $n.synth.log 2>&1
nice -n 5 ./fmv3d-base frames $n/frames -o ${n}w > ${n}w.prep.log 2>&1 && nice -n 5 ./fmv3d-base features ${n}w >> ${n}w.prep.log 2>&1 && nice -n 5 ./fmv3d-base match ${n}w >> ${n}w.prep.log 2>&1
