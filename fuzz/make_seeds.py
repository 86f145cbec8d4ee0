#!/usr/bin/env python3
"""Writes the hand-made seeds of the mesh readers and the camera-path parser into fuzz/corpus/.
The MT file, payload and store seeds come from the tools (bench/fuzz.sh --seeds); see README.md."""
import os, struct

here = os.path.dirname(os.path.abspath(__file__))
V = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0.5)]
F = [(0, 1, 2), (0, 1, 3), (1, 2, 3), (0, 2, 3)]

def put(target, name, data):
    d = os.path.join(here, "corpus", target)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, name), "wb") as f:
        f.write(data if isinstance(data, bytes) else data.encode())

# PLY: ascii, binary LE/BE, with normals, colours, a quad, double coordinates, comments.
def ply_header(fmt, vprops, n_v, n_f, face="property list uchar int vertex_indices"):
    h = f"ply\nformat {fmt} 1.0\ncomment seed\nelement vertex {n_v}\n" + "".join(f"property {p}\n" for p in vprops)
    return h + f"element face {n_f}\n{face}\nend_header\n"
put("reader_ply", "ascii_tet.ply", ply_header("ascii", ["float x", "float y", "float z"], 5, 4) +
    "".join("%g %g %g\n" % v for v in V) + "".join("3 %d %d %d\n" % f for f in F))
put("reader_ply", "ascii_quad_colors.ply", ply_header("ascii", ["double x", "double y", "double z", "float nx", "float ny", "float nz",
    "uchar red", "uchar green", "uchar blue", "uchar alpha"], 4, 1) +
    "0 0 0 0 0 1 255 0 0 255\n1 0 0 0 0 1 0 255 0 255\n1 1 0 0 0 1 0 0 255 255\n0 1 0 0 0 1 9 9 9 255\n4 0 1 2 3\n")
for fmt, e in (("binary_little_endian", "<"), ("binary_big_endian", ">")):
    body = b"".join(struct.pack(e + "fff", *v) for v in V) + b"".join(struct.pack(e + "Biii", 3, *f) for f in F)
    put("reader_ply", f"{fmt}.ply", ply_header(fmt, ["float x", "float y", "float z"], 5, 4).encode() + body)
    body = b"".join(struct.pack(e + "dddBBB", *v, 10, 20, 30) for v in V)
    body += b"".join(struct.pack(e + "BIII", 3, *f) for f in F)
    put("reader_ply", f"{fmt}_double_rgb.ply",
        ply_header(fmt, ["double x", "double y", "double z", "uchar red", "uchar green", "uchar blue"], 5, 4,
                   "property list uchar uint vertex_indices").encode() + body)
# OBJ: v/vn/vt, faces with slashes, negative indices, a quad, comments, groups.
put("reader_obj", "tet.obj", "# seed\n" + "".join("v %g %g %g\n" % v for v in V) + "".join("f %d %d %d\n" % tuple(i + 1 for i in f) for f in F))
put("reader_obj", "slashes.obj", "o thing\ng part\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvn 0 0 1\n"
    "usemtl m\ns off\nf 1/1/1 2/2/1 3/3/1 4/1/1\nf -4//1 -3//1 -2//1\nl 1 2\n")
# OFF: plain, COFF, NOFF, with comments and a quad.
put("reader_off", "tet.off", "OFF\n5 4 0\n" + "".join("%g %g %g\n" % v for v in V) + "".join("3 %d %d %d\n" % f for f in F))
put("reader_off", "quad_comments.off", "OFF # header\n# comment\n4 1 4\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3 255 0 0\n")
put("reader_off", "coff.off", "COFF\n3 1 0\n0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n0 1 0 0 0 255 255\n3 0 1 2\n")
# STL: ascii and binary.
def stl_ascii():
    s = "solid seed\n"
    for f in F:
        s += " facet normal 0 0 1\n  outer loop\n" + "".join("   vertex %g %g %g\n" % V[i] for i in f) + "  endloop\n endfacet\n"
    return s + "endsolid seed\n"
put("reader_stl", "ascii.stl", stl_ascii())
put("reader_stl", "binary.stl", b"binary seed".ljust(80, b"\0") + struct.pack("<I", len(F)) +
    b"".join(struct.pack("<3f", 0, 0, 1) + b"".join(struct.pack("<3f", *V[i]) for i in f) + b"\0\0" for f in F))
# Camera paths: unit and object space, fov changes, optional up.
put("camera_path", "unit.path", "mtrender-camera-path 1\n# seed\nspace unit\nfov 45\n0 -3 1  0 0 0\n1 -2 1  0 0 0  0 0 1\nfov 30\n2 2 2 0 0 0\n")
put("camera_path", "object.path", "space object\n10 20 30 0 0 0 0 1 0\n-5 -5 -5 1 1 1\n")
