"""Writes small PLY files with other tools (plyfile, Open3D, trimesh) for fresco's PLY
compatibility tests, and `ply_fixtures.json` with what each file must read back as.

Run from anywhere:  /work/venv/bin/python core/tests/data/make_ply_fixtures.py
The outputs are committed; CI does not need these tools.

Expected values are the inputs given to the tools, rounded through the storage type each
tool uses (float32 where the file says float), so the Rust test checks fresco's reader
against what the writer meant, not against another reader.
"""
import json
import os

import numpy as np
import open3d as o3d
import plyfile
import trimesh

HERE = os.path.dirname(os.path.abspath(__file__))
expected = {}

# A tetrahedron and a square pyramid with one quad base: small, but every corner differs.
TET_V = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
TET_F = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
PYR_V = np.array([[-1.5, -1.0, 0.25], [1.0, -1.0, 0.25], [1.0, 1.0, 0.25], [-1.0, 1.0, 0.25],
                  [0.1, 0.2, 1.7], [2.5, 0.0, 0.0]])
PYR_POLYS = [[0, 3, 2, 1], [0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4], [1, 5, 2]]


def fan(polys):
    return [[p[0], p[k], p[k + 1]] for p in polys for k in range(1, len(p) - 1)]


def f32(a):
    return np.asarray(a, dtype=np.float32).astype(np.float64).tolist()


def ascii_columns(name, columns):
    """The vertex values an ascii file holds, as printed (the tool chose the digits)."""
    lines = open(path(name)).read().split("end_header\n")[0].splitlines()
    props = [l.split()[-1] for l in lines if l.startswith("property")]
    count = int([l for l in lines if l.startswith("element vertex")][0].split()[2])
    body = open(path(name)).read().split("end_header\n")[1].splitlines()[:count]
    idx = [props.index(c) for c in columns]
    return [[float(row.split()[i]) for i in idx] for row in body]


def record(name, **kw):
    expected[name] = kw


def path(name):
    return os.path.join(HERE, name)


# 1. plyfile, ascii: float positions, uchar/int faces, a comment and obj_info.
v = np.array([tuple(p) for p in TET_V], dtype=[("x", "f4"), ("y", "f4"), ("z", "f4")])
f = np.array([(list(t),) for t in TET_F], dtype=[("vertex_indices", "i4", (3,))])
plyfile.PlyData([plyfile.PlyElement.describe(v, "vertex"), plyfile.PlyElement.describe(f, "face")],
                text=True, comments=["tetrahedron from plyfile"], obj_info=["fresco fixture"]
                ).write(path("plyfile_ascii.ply"))
record("plyfile_ascii.ply", format="ascii", positions=f32(TET_V), faces=TET_F.tolist(),
       comments=["tetrahedron from plyfile"], obj_info=["fresco fixture"])

# 2. plyfile, big endian: double positions, uchar colours, an unknown float property, an
#    unknown element between vertex and face, polygons with a uint index list.
rgb = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255], [10, 20, 30], [200, 100, 50], [1, 2, 3]],
               dtype=np.uint8)
v = np.array([tuple(p) + tuple(c) + (0.5 * i,) for i, (p, c) in enumerate(zip(PYR_V, rgb))],
             dtype=[("x", "f8"), ("y", "f8"), ("z", "f8"), ("red", "u1"), ("green", "u1"),
                    ("blue", "u1"), ("quality", "f4")])
e = np.array([(0, 1), (1, 2)], dtype=[("vertex1", "i4"), ("vertex2", "i4")])
f = np.empty(len(PYR_POLYS), dtype=[("vertex_indices", "O"), ("flags", "i2")])
f["vertex_indices"] = [np.array(p, dtype=np.uint32) for p in PYR_POLYS]
f["flags"] = np.arange(len(PYR_POLYS))
plyfile.PlyData([plyfile.PlyElement.describe(v, "vertex"), plyfile.PlyElement.describe(e, "edge"),
                 plyfile.PlyElement.describe(f, "face", val_types={"vertex_indices": "u4"},
                                             len_types={"vertex_indices": "u1"})],
                byte_order=">").write(path("plyfile_binary_be.ply"))
record("plyfile_binary_be.ply", format="binary_big_endian", positions=PYR_V.tolist(),
       faces=fan(PYR_POLYS), colors=rgb.tolist())

# 3. Hand-written header with the sized type aliases (int8 ... float64), little endian,
#    float colours (0..1) and a list property inside the vertex element.
alias_v = PYR_V[:5]
# No channel lands near a half-way point of x * 255, where rounding conventions differ.
cols = np.array([[0.0, 0.6, 1.0], [1.0, 1.0, 1.0], [0.2, 0.4, 0.6], [0.0, 0.0, 0.0], [0.8, 0.15, 0.35]])
with open(path("aliases_binary_le.ply"), "wb") as out:
    out.write(b"ply\nformat binary_little_endian 1.0\ncomment sized type names\n"
              b"element vertex 5\nproperty int8 tag\nproperty float32 x\nproperty float32 y\n"
              b"property float64 z\nproperty list uint8 int16 neighbours\nproperty float32 red\n"
              b"property float32 green\nproperty float32 blue\n"
              b"element face 5\nproperty list uint8 int32 vertex_index\nend_header\n")
    for i, (p, c) in enumerate(zip(alias_v, cols)):
        out.write(np.array([-i], "<i1").tobytes() + np.array(p[:2], "<f4").tobytes()
                  + np.array([p[2]], "<f8").tobytes() + np.array([2], "<u1").tobytes()
                  + np.array([i, i + 1], "<i2").tobytes() + np.array(c, "<f4").tobytes())
    for poly in PYR_POLYS[:5]:
        out.write(np.array([len(poly)], "<u1").tobytes() + np.array(poly, "<i4").tobytes())
alias_pos = [[float(np.float32(p[0])), float(np.float32(p[1])), float(p[2])] for p in alias_v]
record("aliases_binary_le.ply", format="binary_little_endian", positions=alias_pos,
       faces=fan(PYR_POLYS[:5]),
       colors=[[int(round(float(np.float32(x)) * 255.0)) for x in c] for c in cols])

# 4. MeshLab's layout for wedge (per-corner) texture coordinates: a texcoord list and a
#    texnumber per face, v up. Written with plyfile in MeshLab's header order.
uv = {0: [(0.0, 0.0), (0.0, 1.0), (1.0, 1.0), (1.0, 0.0)], 1: [(0.1, 0.2), (0.3, 0.2), (0.2, 0.9)]}
polys = [PYR_POLYS[0], PYR_POLYS[1]]
f = np.empty(2, dtype=[("vertex_indices", "O"), ("texcoord", "O"), ("texnumber", "i4")])
f["vertex_indices"] = [np.array(p, dtype=np.int32) for p in polys]
f["texcoord"] = [np.array(uv[i], dtype=np.float32).ravel() for i in range(2)]
f["texnumber"] = [0, 1]
v = np.array([tuple(p) for p in PYR_V[:5]], dtype=[("x", "f4"), ("y", "f4"), ("z", "f4")])
plyfile.PlyData([plyfile.PlyElement.describe(v, "vertex"),
                 plyfile.PlyElement.describe(f, "face", val_types={"vertex_indices": "i4", "texcoord": "f4"},
                                             len_types={"vertex_indices": "u1", "texcoord": "u1"})],
                comments=["TextureFile a.png", "TextureFile b.png"]).write(path("meshlab_texcoords_le.ply"))
corner_uvs = []
for i, p in enumerate(polys):
    c = [[float(np.float32(u)), float(np.float32(1.0 - np.float32(vv)))] for u, vv in uv[i]]
    corner_uvs += [[c[0], c[k], c[k + 1]] for k in range(1, len(p) - 1)]
record("meshlab_texcoords_le.ply", format="binary_little_endian", positions=f32(PYR_V[:5]),
       faces=fan(polys), corner_uvs=corner_uvs, face_textures=[0, 0, 1])

# 5. Open3D: a triangle mesh with vertex normals and colours, binary and ascii; a point cloud.
mesh = o3d.geometry.TriangleMesh()
mesh.vertices = o3d.utility.Vector3dVector(PYR_V)
mesh.triangles = o3d.utility.Vector3iVector(np.array(fan(PYR_POLYS)))
normals = PYR_V / np.linalg.norm(PYR_V, axis=1, keepdims=True)
mesh.vertex_normals = o3d.utility.Vector3dVector(normals)
rgb8 = np.array([[0, 64, 255], [12, 34, 56], [255, 255, 255], [7, 8, 9], [100, 150, 200], [0, 0, 0]])
mesh.vertex_colors = o3d.utility.Vector3dVector(rgb8 / 255.0)
for ascii_, name in [(False, "open3d_mesh_binary.ply"), (True, "open3d_mesh_ascii.ply")]:
    o3d.io.write_triangle_mesh(path(name), mesh, write_ascii=ascii_, write_vertex_normals=True,
                               write_vertex_colors=True)
    header = open(path(name), "rb").read(1024).split(b"end_header")[0].decode()
    pos_t = "float" if "property float x" in header else "double"
    nrm_t = "float" if "property float nx" in header else "double"
    if ascii_:
        # Open3D's ascii writer prints 6 significant digits (%g): that is what the file holds.
        pos, nrm = ascii_columns(name, "x y z".split()), ascii_columns(name, "nx ny nz".split())
    else:
        pos = f32(PYR_V) if pos_t == "float" else PYR_V.tolist()
        nrm = f32(normals) if nrm_t == "float" else normals.tolist()
    record(name, format="ascii" if ascii_ else "binary_little_endian",
           positions=pos, faces=fan(PYR_POLYS), normals=nrm, colors=rgb8.tolist())

pcd = o3d.geometry.PointCloud()
rng = np.random.default_rng(7)
pts = rng.normal(size=(50, 3))
pcd.points = o3d.utility.Vector3dVector(pts)
pcd.normals = o3d.utility.Vector3dVector(pts / np.linalg.norm(pts, axis=1, keepdims=True))
pcol = rng.integers(0, 256, size=(50, 3))
pcd.colors = o3d.utility.Vector3dVector(pcol / 255.0)
o3d.io.write_point_cloud(path("open3d_points.ply"), pcd, write_ascii=False)
header = open(path("open3d_points.ply"), "rb").read(1024).split(b"end_header")[0].decode()
record("open3d_points.ply", format="binary_little_endian",
       positions=f32(pts) if "property float x" in header else pts.tolist(), faces=[],
       normals=(f32 if "property float nx" in header else (lambda a: a.tolist()))(
           pts / np.linalg.norm(pts, axis=1, keepdims=True)),
       colors=pcol.tolist())

# 6. trimesh: binary and ascii, with vertex colours (trimesh adds alpha).
tm = trimesh.Trimesh(vertices=PYR_V, faces=np.array(fan(PYR_POLYS)), process=False)
rgba = np.hstack([rgb8, np.full((6, 1), 255)]).astype(np.uint8)
tm.visual.vertex_colors = rgba
for enc, name in [("binary", "trimesh_binary.ply"), ("ascii", "trimesh_ascii.ply")]:
    data = trimesh.exchange.ply.export_ply(tm, encoding=enc, include_attributes=False)
    open(path(name), "wb").write(data)
    header = data.split(b"end_header")[0].decode()
    record(name, format="ascii" if enc == "ascii" else "binary_little_endian",
           positions=ascii_columns(name, "x y z".split()) if enc == "ascii" else f32(PYR_V),
           faces=fan(PYR_POLYS), colors=rgb8.tolist())
    assert "property float x" in header

with open(path("ply_fixtures.json"), "w") as out:
    json.dump(expected, out, indent=1, sort_keys=True)
    out.write("\n")
print("wrote", len(expected), "fixtures")
