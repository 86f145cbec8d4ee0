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
# PLY triangle strips: -1 ends a strip, a repeated index joins two; ascii and binary.
S = [0, 1, 2, 3, -1, 4, 3, 3, 2, 1]
strip_header = lambda fmt: (f"ply\nformat {fmt} 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\n"
                            "element tristrips 1\nproperty list int int vertex_indices\nend_header\n")
put("reader_ply", "ascii_tristrips.ply", strip_header("ascii") + "".join("%g %g %g\n" % v for v in V) +
    "%d %s\n" % (len(S), " ".join(map(str, S))))
put("reader_ply", "binary_tristrips.ply", strip_header("binary_little_endian").encode() +
    b"".join(struct.pack("<fff", *v) for v in V) + struct.pack("<i", len(S)) + b"".join(struct.pack("<i", i) for i in S))
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

# glTF: GLB and .gltf (base64 data URI), indexed (u8/u16/u32) and not, node trees with TRS and a
# matrix, strips and fans, normals and RGBA8/float colours, interleaved (byteStride) views,
# KHR_mesh_quantization's normalized int16 positions, a sparse accessor and points (refused, skipped).
# The compressed extensions' seeds come from the tools (bench/fuzz.sh --seeds: mtextract --meshopt,
# fuzz_seed_gltf for Draco).
import base64, json

class Gltf:
    def __init__(self):
        self.j = {"asset": {"version": "2.0"}, "buffers": [], "bufferViews": [], "accessors": [], "meshes": [], "nodes": []}
        self.bin = b""
    def view(self, data, stride=None):
        self.bin += b"\0" * (-len(self.bin) % 4)
        v = {"buffer": 0, "byteOffset": len(self.bin), "byteLength": len(data)}
        if stride: v["byteStride"] = stride
        self.j["bufferViews"].append(v)
        self.bin += data
        return len(self.j["bufferViews"]) - 1
    def accessor(self, view, ctype, count, typ, **kw):
        self.j["accessors"].append(dict(bufferView=view, componentType=ctype, count=count, type=typ, **kw))
        return len(self.j["accessors"]) - 1
    def positions(self, pts):
        lo = [min(p[k] for p in pts) for k in range(3)]
        hi = [max(p[k] for p in pts) for k in range(3)]
        return self.accessor(self.view(b"".join(struct.pack("<3f", *p) for p in pts)), 5126, len(pts), "VEC3", min=lo, max=hi)
    def indices(self, idx, ctype):
        fmt = {5121: "B", 5123: "H", 5125: "I"}[ctype]
        return self.accessor(self.view(struct.pack("<%d%s" % (len(idx), fmt), *idx)), ctype, len(idx), "SCALAR")
    def mesh(self, *prims):
        self.j["meshes"].append({"primitives": list(prims)})
        return len(self.j["meshes"]) - 1
    def glb(self):
        self.bin += b"\0" * (-len(self.bin) % 4)
        self.j["buffers"] = [{"byteLength": len(self.bin)}]
        text = json.dumps(self.j, separators=(",", ":")).encode()
        text += b" " * (-len(text) % 4)
        total = 12 + 8 + len(text) + 8 + len(self.bin)
        return struct.pack("<III", 0x46546C67, 2, total) + struct.pack("<II", len(text), 0x4E4F534A) + text + \
            struct.pack("<II", len(self.bin), 0x004E4942) + self.bin
    def gltf(self):
        self.j["buffers"] = [{"byteLength": len(self.bin),
                              "uri": "data:application/octet-stream;base64," + base64.b64encode(self.bin).decode()}]
        return json.dumps(self.j, indent=1)

tri = [i for f in F for i in f]
g = Gltf()
m0 = g.mesh({"attributes": {"POSITION": g.positions(V)}, "indices": g.indices(tri, 5123)})
m1 = g.mesh({"attributes": {"POSITION": g.positions(V)}, "indices": g.indices(tri, 5125), "mode": 4},
            {"attributes": {"POSITION": g.positions(V)}, "indices": g.indices([0, 1, 2, 3, 4], 5121), "mode": 5})
g.j["nodes"] = [{"mesh": m0, "translation": [500000.0, 4000000.0, 10.0], "children": [1, 2]},
                {"mesh": m1, "rotation": [0, 0, 0.3826834, 0.9238795], "scale": [1.5, 1.5, -1.5]},
                {"mesh": m0, "matrix": [2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 2, 0, 1, 2, 3, 1]}]
g.j["scenes"] = [{"nodes": [0]}]
g.j["scene"] = 0
put("reader_gltf", "nodes_indexed.glb", g.glb())
put("reader_gltf", "nodes_indexed.gltf", g.gltf())

# Interleaved position + normal + colour (stride 28), a fan, no scenes (every mesh once).
g = Gltf()
inter = b"".join(struct.pack("<3f3f4B", *p, 0, 0, 1, 200, 100, 50, 255) for p in V)
iv = g.view(inter, stride=28)
pa = g.accessor(iv, 5126, len(V), "VEC3", byteOffset=0, min=[0, 0, 0], max=[1, 1, 1])
na = g.accessor(iv, 5126, len(V), "VEC3", byteOffset=12)
ca = g.accessor(iv, 5121, len(V), "VEC4", byteOffset=24, normalized=True)
g.mesh({"attributes": {"POSITION": pa, "NORMAL": na, "COLOR_0": ca}, "mode": 6},
       {"attributes": {"POSITION": pa, "TEXCOORD_0": na}, "mode": 0})
put("reader_gltf", "interleaved_fan.glb", g.glb())

# KHR_mesh_quantization: normalized int16 positions, int8 normals, float RGB colours, a strip.
g = Gltf()
qp = g.accessor(g.view(b"".join(struct.pack("<4h", int(p[0] * 32767), int(p[1] * 32767), int(p[2] * 32767), 0) for p in V), stride=8),
                5122, len(V), "VEC3", normalized=True, min=[0, 0, 0], max=[1, 1, 1])
qn = g.accessor(g.view(b"".join(struct.pack("<4b", 0, 0, 127, 0) for _ in V)), 5120, len(V), "VEC3", normalized=True)
qc = g.accessor(g.view(b"".join(struct.pack("<3f", 0.5, 0.25, 1.0) for _ in V)), 5126, len(V), "VEC3")
g.mesh({"attributes": {"POSITION": qp, "NORMAL": qn, "COLOR_0": qc}, "mode": 5})
g.j["nodes"] = [{"mesh": 0, "scale": [0.001, 0.001, 0.001]}]
g.j["scenes"] = [{"nodes": [0]}]
g.j["extensionsUsed"] = g.j["extensionsRequired"] = ["KHR_mesh_quantization"]
put("reader_gltf", "quantized_strip.gltf", g.gltf())

# A sparse accessor (refused) and a points primitive.
g = Gltf()
sp = g.positions(V)
g.j["accessors"][sp]["sparse"] = {"count": 1, "indices": {"bufferView": g.view(struct.pack("<H", 1)), "componentType": 5123},
                                  "values": {"bufferView": g.view(struct.pack("<3f", 9, 9, 9))}}
g.mesh({"attributes": {"POSITION": sp}, "mode": 0}, {"attributes": {"POSITION": sp}})
put("reader_gltf", "sparse_points.glb", g.glb())
