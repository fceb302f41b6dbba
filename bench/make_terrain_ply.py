#!/usr/bin/env python3
# A binary PLY (x y z nx ny nz red green blue) of N points on a 500 x 500 m terrain-like surface, the input of
# the tiles-stage figures in bench/results/console-server.md. Usage: make_terrain_ply.py N OUT.ply
import struct, math, random, sys
n = int(sys.argv[1]); out = sys.argv[2]
random.seed(1)
hdr = ("ply\nformat binary_little_endian 1.0\nelement vertex %d\n" % n +
       "property float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\n"
       "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n")
rec = struct.Struct('<6f3B')
with open(out, 'wb') as f:
    f.write(hdr.encode())
    chunk = 200000
    for start in range(0, n, chunk):
        m = min(chunk, n - start)
        buf = bytearray(rec.size * m)
        for i in range(m):
            x = random.random() * 500; y = random.random() * 500
            z = 20 * math.sin(x / 40) * math.cos(y / 55) + 3 * math.sin(x / 7)
            rec.pack_into(buf, i * rec.size, x, y, z, 0.0, 0.0, 1.0, int(x / 2), int(y / 2), 128)
        f.write(buf)
