#!/bin/bash
# se.sh BIN TEMPLATE_WS OUT_WS TRUTH [sparse args]: sparse on a hard-linked copy of the template's frames/features/matches, then evaluate
cd /work/runs/pp11
bin=$1; tpl=$2; out=$3; truth=$4; shift 4
rm -rf $out; mkdir -p $out; cp -rl $tpl/frames $tpl/features $tpl/matches $out/
/usr/bin/time -f "%e s wall %U s user %M kB" nice -n 5 $bin sparse $out "$@" > $out.log 2>&1
$bin evaluate-sparse $out --truth $truth > $out.eval 2>&1
