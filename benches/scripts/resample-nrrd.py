#!/usr/bin/env python3
"""A thin-slice CT stand-in: a 16-bit NRRD (gzip or raw, attached) resampled
linearly along z to NZ slices over the same extent, written as an
uncompressed attached NRRD (what `--distributed` reads brick by brick).
Standard library only.

Usage: benches/scripts/resample-nrrd.py IN.nrrd OUT.nrrd NZ
(e.g. the shared chest CT, 512x512x48 at 5 mm, to 413 slices of 0.57 mm)."""
import array, gzip, os, re, sys

src, dst, NZ = sys.argv[1], sys.argv[2], int(sys.argv[3])
raw = open(src, 'rb').read()
end = raw.index(b'\n\n') + 2
head = raw[:end].decode()
field = lambda k: re.search(r'^%s: (.*)$' % k, head, re.M).group(1).strip()
assert field('type') in ('short', 'int16', 'signed short') and field('dimension') == '3' and field('endian') == 'little'
nx, ny, nz = map(int, field('sizes').split())
body = gzip.decompress(raw[end:]) if field('encoding') in ('gzip', 'gz') else raw[end:]
data = array.array('h', body)
assert len(data) == nx * ny * nz
dirs = re.findall(r'\(([^)]*)\)', field('space directions'))
dz = [float(x) * (nz - 1) / (NZ - 1) for x in dirs[2].split(',')]
head = head.replace(field('sizes'), '%d %d %d' % (nx, ny, NZ)).replace(field('encoding'), 'raw')
head = head.replace('(%s)' % dirs[2], '(%s)' % ','.join(repr(x) for x in dz))
plane = nx * ny
with open(dst + '.tmp', 'wb') as f:
    f.write(head.encode())
    for z in range(NZ):
        p = z * (nz - 1) / (NZ - 1)
        i = min(int(p), nz - 2)
        t = p - i
        a, b = data[i * plane:(i + 1) * plane], data[(i + 1) * plane:(i + 2) * plane]
        f.write((a if t < 1e-9 else array.array('h', [int(round(x + t * (y - x))) for x, y in zip(a, b)])).tobytes())
os.replace(dst + '.tmp', dst)
