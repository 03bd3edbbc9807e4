#!/usr/bin/env python3
"""Convert binary PGM (P5, 8-bit) files to PNG with the standard library only.

usage: pgm2png.py OUT.png IN1.pgm [IN2.pgm ...] [--flip]

Several inputs are placed side by side (same height required) with a 4-pixel
grey gap, which makes it easy to look at a rotation sequence at once.
--flip writes every image bottom-up (row 0 at the bottom), i.e. the y-up
orientation VolPack's window uses (see benches/scripts/volpack/README.md).
"""
import struct
import sys
import zlib


def read_pgm(path):
    with open(path, "rb") as f:
        data = f.read()
    tokens = []
    pos = 0
    while len(tokens) < 4:
        while data[pos:pos + 1].isspace():
            pos += 1
        if data[pos:pos + 1] == b"#":
            while data[pos:pos + 1] not in (b"\n", b""):
                pos += 1
            continue
        start = pos
        while not data[pos:pos + 1].isspace():
            pos += 1
        tokens.append(data[start:pos])
    if tokens[0] != b"P5" or int(tokens[3]) > 255:
        raise SystemExit(f"{path}: only 8-bit binary PGM (P5) is supported")
    w, h = int(tokens[1]), int(tokens[2])
    pix = data[pos + 1:pos + 1 + w * h]
    if len(pix) != w * h:
        raise SystemExit(f"{path}: truncated")
    return w, h, pix


def write_png(path, w, h, rows):
    raw = b"".join(b"\x00" + r for r in rows)

    def chunk(tag, body):
        c = struct.pack(">I", len(body)) + tag + body
        return c + struct.pack(">I", zlib.crc32(tag + body) & 0xFFFFFFFF)

    png = b"\x89PNG\r\n\x1a\n"
    png += chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(raw, 6))
    png += chunk(b"IEND", b"")
    with open(path, "wb") as f:
        f.write(png)


def main(argv):
    flip = "--flip" in argv
    args = [a for a in argv if a != "--flip"]
    if len(args) < 2:
        raise SystemExit(__doc__)
    out, ins = args[0], args[1:]
    imgs = [read_pgm(p) for p in ins]
    h = imgs[0][1]
    if any(im[1] != h for im in imgs):
        raise SystemExit("all inputs must have the same height")
    gap = 4
    total_w = sum(im[0] for im in imgs) + gap * (len(imgs) - 1)
    rows = []
    for y in range(h):
        parts = []
        for i, (w, _, pix) in enumerate(imgs):
            yy = h - 1 - y if flip else y
            if i:
                parts.append(b"\x60" * gap)
            parts.append(pix[yy * w:(yy + 1) * w])
        rows.append(b"".join(parts))
    write_png(out, total_w, h, rows)


if __name__ == "__main__":
    main(sys.argv[1:])
