#!/usr/bin/env python3
"""png_compare.py A.png B.png MAX_PERCENT [THRESHOLD]: compares two 8-bit RGB PNGs of the
same size pixel by pixel (standard library only: zlib and the five PNG filters). A pixel
differs when a channel differs by more than THRESHOLD (default 40 of 255). Prints the share
of differing pixels and the mean absolute difference; exits 1 when the share exceeds
MAX_PERCENT or the images do not match in size, 2 on an unreadable file."""
import struct
import sys
import zlib


def read_png(path):
    with open(path, "rb") as f:
        data = f.read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError(f"{path}: not a PNG")
    pos, idat, width, height, ctype = 8, b"", 0, 0, 0
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            width, height, depth, ctype, _, _, interlace = struct.unpack(">IIBBBBB", body)
            if depth != 8 or ctype not in (2, 6) or interlace:
                raise ValueError(f"{path}: only 8-bit RGB/RGBA, not interlaced")
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    bpp = 3 if ctype == 2 else 4
    raw = zlib.decompress(idat)
    stride = width * bpp
    out = bytearray(height * stride)
    prev = bytearray(stride)
    for y in range(height):
        ft = raw[y * (stride + 1)]
        line = bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b = prev[i]
            c = prev[i - bpp] if i >= bpp else 0
            if ft == 1:
                line[i] = (line[i] + a) & 255
            elif ft == 2:
                line[i] = (line[i] + b) & 255
            elif ft == 3:
                line[i] = (line[i] + (a + b) // 2) & 255
            elif ft == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        out[y * stride:(y + 1) * stride] = line
        prev = line
    return width, height, bpp, out


def main():
    a, b, max_pct = sys.argv[1], sys.argv[2], float(sys.argv[3])
    thr = int(sys.argv[4]) if len(sys.argv) > 4 else 40
    try:
        wa, ha, ba, pa = read_png(a)
        wb, hb, bb, pb = read_png(b)
    except (OSError, ValueError, zlib.error) as e:
        print(f"png_compare: {e}")
        return 2
    if (wa, ha) != (wb, hb):
        print(f"png_compare: sizes differ: {wa}x{ha} and {wb}x{hb}")
        return 1
    differ, total = 0, 0
    for i in range(wa * ha):
        da = [abs(pa[i * ba + k] - pb[i * bb + k]) for k in range(3)]
        total += sum(da)
        differ += max(da) > thr
    pct = 100.0 * differ / (wa * ha)
    print(f"png_compare: {differ} of {wa * ha} pixels differ by more than {thr}/255 ({pct:.3f}%), "
          f"mean |difference| {total / (3 * wa * ha):.2f}/255")
    return 0 if pct <= max_pct else 1


if __name__ == "__main__":
    sys.exit(main())
