#!/bin/bash
# prep.sh BIN NAME SEED DU,DV [synth args]: a 36-frame 960x540 town orbit and its workspace (frames/features/matches)
cd /work/runs/pp11
bin=$1; n=$2; s=$3; o=$4; shift 4
nice -n 5 $bin synth --scene town --path orbit --frames 36 --size 960x540 --seed $s --principal-offset $o --no-scene "$@" -o $n > $n.synth.log 2>&1
nice -n 5 $bin frames $n/frames -o ${n}w > ${n}w.prep.log 2>&1 && nice -n 5 $bin features ${n}w >> ${n}w.prep.log 2>&1 && nice -n 5 $bin match ${n}w >> ${n}w.prep.log 2>&1
