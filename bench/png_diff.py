#!/usr/bin/env python3
# bench/png_diff.py A.png B.png: pixels whose largest RGB channel difference is over 40, and the
# mean of that difference (the render tests' imageDiff), for two PNGs of one size (8-bit RGB/RGBA,
# as mtrender writes them). Standard library only.
import struct
import sys
import zlib


def readpng(p):
    """(width, height, bytes per pixel, pixel bytes) of an 8-bit, non-interlaced PNG."""
    d = open(p,'rb').read(); assert d[:8] == b'\x89PNG\r\n\x1a\n'
    pos = 8; idat = b''; w = h = 0
    while pos < len(d):
        n, t = struct.unpack('>I4s', d[pos:pos+8]); c = d[pos+8:pos+8+n]; pos += 12 + n
        if t == b'IHDR': w, h, bd, ct = struct.unpack('>IIBB', c[:10])
        elif t == b'IDAT': idat += c
    raw = zlib.decompress(idat); bpp = 4 if ct == 6 else 3; stride = w * bpp
    out = bytearray(); prev = bytearray(stride); i = 0
    for y in range(h):
        f = raw[i]; i += 1; line = bytearray(raw[i:i+stride]); i += stride
        for x in range(stride):
            a = line[x-bpp] if x >= bpp else 0; b = prev[x]; cc = prev[x-bpp] if x >= bpp else 0
            if f == 1: line[x] = (line[x] + a) & 255
            elif f == 2: line[x] = (line[x] + b) & 255
            elif f == 3: line[x] = (line[x] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - cc; pa, pb, pc = abs(p-a), abs(p-b), abs(p-cc)
                line[x] = (line[x] + (a if pa <= pb and pa <= pc else b if pb <= pc else cc)) & 255
        out += line; prev = line
    return w, h, bpp, out
w, h, bpp, a = readpng(sys.argv[1]); _, _, bpp2, b = readpng(sys.argv[2])
differ = 0; tot = 0
for i in range(w*h):
    d = max(abs(a[i*bpp+k] - b[i*bpp2+k]) for k in range(3)); differ += d > 40; tot += d
print("differ>40: %d of %d (%.3f%%), mean %.3f" % (differ, w*h, 100.0*differ/(w*h), tot/(w*h)))
