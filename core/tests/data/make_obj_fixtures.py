"""Writes small textured OBJ files with trimesh and Open3D for fresco's OBJ compatibility
tests, and `obj_fixtures.json` with what each must read back as (UVs in fresco's v-down
convention, i.e. 1 - v of the file).

Run: /work/venv/bin/python core/tests/data/make_obj_fixtures.py   (outputs are committed)
"""
import json
import os

import numpy as np
import open3d as o3d
import trimesh
from PIL import Image

HERE = os.path.dirname(os.path.abspath(__file__))
expected = {}

# A unit square split in two triangles, with distinct UVs per corner and a 4x4 texture.
V = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
F = np.array([[0, 1, 2], [0, 2, 3]])
UV = np.array([[0.125, 0.25], [0.875, 0.25], [0.875, 0.75], [0.125, 0.75]])
tex = Image.fromarray((np.arange(48, dtype=np.uint8).reshape(4, 4, 3) * 5))

# trimesh: writes an .obj, an .mtl and the texture image into one folder.
out = os.path.join(HERE, "trimesh_obj")
os.makedirs(out, exist_ok=True)
tm = trimesh.Trimesh(vertices=V, faces=F, process=False,
                     visual=trimesh.visual.TextureVisuals(uv=UV, image=tex))
files = trimesh.exchange.export.export_mesh(tm, os.path.join(out, "square.obj"), file_type="obj",
                                            include_normals=True)
mtl = [f for f in os.listdir(out) if f.endswith(".mtl")]
png = [f for f in os.listdir(out) if f.endswith(".png")]
expected["trimesh_obj/square.obj"] = dict(
    positions=V.tolist(), faces=F.tolist(),
    corner_uvs=[[[UV[v][0], 1.0 - UV[v][1]] for v in f] for f in F],
    textures=png)

# Open3D: per-corner UVs (triangle_uvs) and a texture.
out = os.path.join(HERE, "open3d_obj")
os.makedirs(out, exist_ok=True)
mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F))
corner = np.array([UV[v] for f in F for v in f])
corner[4] = [0.5, 0.5]  # a seam: vertex 2 has different UVs in its two faces
mesh.triangle_uvs = o3d.utility.Vector2dVector(corner)
mesh.triangle_material_ids = o3d.utility.IntVector([0, 0])
mesh.textures = [o3d.geometry.Image(np.asarray(tex))]
mesh.compute_vertex_normals()
o3d.io.write_triangle_mesh(os.path.join(out, "square.obj"), mesh, write_triangle_uvs=True)
png = sorted(f for f in os.listdir(out) if f.endswith(".png"))
expected["open3d_obj/square.obj"] = dict(
    positions=V.tolist(), faces=F.tolist(),
    corner_uvs=[[[corner[3 * i + c][0], 1.0 - corner[3 * i + c][1]] for c in range(3)]
                for i in range(2)],
    textures=png)

with open(os.path.join(HERE, "obj_fixtures.json"), "w") as f:
    json.dump(expected, f, indent=1, sort_keys=True)
    f.write("\n")
print("wrote", len(expected), "OBJ fixtures")
