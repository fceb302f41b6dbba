#!/bin/bash
# sev.sh BIN TPL OUT TRUTH: like selfcal8/sparse_eval.sh, hard-linked copy of the template, summary line
cd /work/runs/pp10
bin=$1; tpl=$2; out=$3; truth=$4; shift 4
rm -rf $out; mkdir -p $out; cp -rl $tpl/frames $tpl/features $tpl/matches $out/
/usr/bin/time -f "%e s wall %U s user" nice -n 5 $bin sparse $out "$@" > $out.log 2>&1
$bin evaluate-sparse $out --truth $truth > $out.eval 2>&1
