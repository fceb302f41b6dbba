#!/usr/bin/env python3
"""CPU seconds to compile a random sample of the build's translation units, Release flags against the sanitizer
run's (ASan + UBSan, -O1 -g1): an estimate of what a second, sanitized build adds to CI.
  bench/compile_cost.py [BUILD_DIR] [SAMPLE] [SEED]     (BUILD_DIR has compile_commands.json; default build, 8, 3)
CPU time (user + system of the compiler) is measured, so the estimate holds on a loaded machine too."""
import json, os, random, resource, shlex, subprocess, sys

build = sys.argv[1] if len(sys.argv) > 1 else 'build'
count = int(sys.argv[2]) if len(sys.argv) > 2 else 8
random.seed(int(sys.argv[3]) if len(sys.argv) > 3 else 3)
units = json.load(open(os.path.join(build, 'compile_commands.json')))
SANITIZE = ['-O1', '-g1', '-DNDEBUG', '-fsanitize=address,undefined', '-fno-sanitize-recover=all',
            '-fno-omit-frame-pointer']


def cpu_seconds(cmd, cwd):
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(cmd, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime


def compile_args(entry):
    args = shlex.split(entry['command'])
    if args[0] == 'ccache':
        args = args[1:]
    out, skip = [], 0
    for a in args:
        if skip:
            skip -= 1
        elif a in ('-MT', '-MF', '-o'):
            skip = 1
        elif a != '-MD':
            out.append(a)
    return out + ['-o', os.devnull]


total = {'release': 0.0, 'sanitize': 0.0}
for entry in random.sample(units, min(count, len(units))):
    release = compile_args(entry)
    sanitize = [a for a in release if a not in ('-O3', '-O2', '-DNDEBUG')] + SANITIZE
    r, s = cpu_seconds(release, entry['directory']), cpu_seconds(sanitize, entry['directory'])
    total['release'] += r
    total['sanitize'] += s
    print(f"{r:6.1f} {s:6.1f}  {os.path.basename(entry['file'])}", flush=True)
n = min(count, len(units))
print(f"sample of {n} of {len(units)} units: release {total['release']:.1f} CPU-s, sanitize {total['sanitize']:.1f} "
      f"CPU-s (x{total['sanitize'] / max(total['release'], 1e-9):.2f}); whole build about "
      f"{total['release'] / n * len(units) / 60:.0f} / {total['sanitize'] / n * len(units) / 60:.0f} CPU-minutes")
