"""The MeshLab texture reference of issue 14: textures a mesh from registered photos with
MeshLab's own filters (through pymeshlab) and writes each result as a GLB that
`fresco eval texture` scores exactly as it scores fresco's model.glb (same renderer, same
held-out photos, same masks), so the two are compared on equal terms.

Filters (pymeshlab names, MeshLab defaults unless said):
  param   "Parameterization + texturing from registered rasters"
          (compute_texcoord_parametrization_and_texture_from_registered_rasters): MeshLab's
          own charts (one raster per face) and texture, colour correction on, at
          --texture-size (default 2048);
  project "Project active rasters color to current mesh, filling the texture"
          (compute_color_and_texture_from_active_rasters_projection) on the param filter's
          UVs: every raster blended per texel (angle, distance, border, silhouette weights);
  vertex  "Project active rasters color to current mesh"
          (compute_color_from_active_rasters_projection): per-vertex colour from rasters.

Cameras: the COLMAP text model's registered images (minus --exclude) become a Bundler
project (bundle.out + image list) that MeshLab imports; Bundler's camera has one focal length,
the principal point at the image centre and radial k1, k2 (looking down -z, y up: the COLMAP
rotation and translation with their y and z rows negated). A camera outside that (fx != fy,
an off-centre principal point beyond 0.5 px, tangential distortion) is refused with its id.
Whether MeshLab's raster filters apply Bundler's k1/k2 is not documented; the benchmark feeds
distortion-free cameras.

Usage (bench/texture_meshlab.sh runs it; the raster filters need OpenGL: an X server with GLX,
`xvfb-run -a -s "-screen 0 1280x1024x24 +extension GLX"`, and the xcb libraries
bench/texture_meshlab.sh installs):
  python meshlab_texture.py --colmap <sparse dir> --images <dir> --mesh <mesh.ply>
      [--exclude a.png,b.png] [--texture-size 2048] -o <out dir>
Writes <out>/meshlab_param.glb, meshlab_project.glb, meshlab_vertex.glb, the param filter's
texture PNG, and prints (and writes <out>/meshlab.json) each filter's wall and CPU seconds."""
import argparse
import json
import math
import os
import resource
import shutil
import struct
import sys
import time
from pathlib import Path

import importlib.util

import numpy as np

# pymeshlab ships Qt without its platform plugins; PyQt5-Qt5 has them (xcb and its GLX
# integration, which the raster filters need for their OpenGL depth renders under xvfb).
_pyqt = importlib.util.find_spec("PyQt5")
if _pyqt is not None and "QT_PLUGIN_PATH" not in os.environ:
    os.environ["QT_PLUGIN_PATH"] = str(Path(list(_pyqt.submodule_search_locations)[0]) / "Qt5" / "plugins")
import pymeshlab  # noqa: E402


def read_colmap_text(model: Path):
    """cameras {id: (model, w, h, params)}, images [(name, camera id, qvec, tvec)]."""
    cameras = {}
    for line in (model / "cameras.txt").read_text().splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        f = line.split()
        cameras[int(f[0])] = (f[1], int(f[2]), int(f[3]), [float(x) for x in f[4:]])
    images = []
    lines = [l for l in (model / "images.txt").read_text().splitlines() if not l.startswith("#")]
    for line in lines[0::2]:
        f = line.split()
        if len(f) < 10:
            continue
        q = [float(x) for x in f[1:5]]
        t = [float(x) for x in f[5:8]]
        images.append((f[9], int(f[8]), q, t))
    return cameras, images


def quat_to_matrix(q):
    w, x, y, z = q
    n = math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def bundler_intrinsics(cam_id, cam):
    """(f, k1, k2) of a COLMAP camera Bundler can express, or SystemExit naming it."""
    model, w, h, p = cam
    if model in ("SIMPLE_PINHOLE", "SIMPLE_RADIAL", "RADIAL"):
        f, cx, cy = p[0], p[1], p[2]
        k1 = p[3] if len(p) > 3 else 0.0
        k2 = p[4] if len(p) > 4 else 0.0
    elif model == "PINHOLE":
        if abs(p[0] - p[1]) > 1e-6 * p[0]:
            sys.exit(f"camera {cam_id}: PINHOLE with fx {p[0]} != fy {p[1]} (Bundler has one focal)")
        f, cx, cy, k1, k2 = p[0], p[2], p[3], 0.0, 0.0
    else:
        sys.exit(f"camera {cam_id}: model {model} has no Bundler equivalent")
    if abs(cx - w / 2) > 0.5 or abs(cy - h / 2) > 0.5:
        sys.exit(f"camera {cam_id}: principal point ({cx}, {cy}) is not the image centre ({w / 2}, {h / 2})")
    return f, k1, k2


def write_bundler(cameras, images, image_dir: Path, work: Path):
    """bundle.out and list.txt (absolute image paths) in `work`; returns their paths."""
    flip = np.diag([1.0, -1.0, -1.0])
    out = [f"# Bundle file v0.3", f"{len(images)} 0"]
    names = []
    for name, cam_id, q, t in images:
        f, k1, k2 = bundler_intrinsics(cam_id, cameras[cam_id])
        r = flip @ quat_to_matrix(q)
        tb = flip @ np.array(t)
        out.append(f"{f:.10g} {k1:.10g} {k2:.10g}")
        out += [" ".join(f"{v:.12g}" for v in row) for row in r]
        out.append(" ".join(f"{v:.12g}" for v in tb))
        path = image_dir / name
        if not path.is_file():
            sys.exit(f"{path}: photo of image {name} not found")
        names.append(str(path.resolve()))
    bundle = work / "bundle.out"
    bundle.write_text("\n".join(out) + "\n")
    lst = work / "list.txt"
    lst.write_text("\n".join(names) + "\n")
    return bundle, lst


def srgb_to_linear(c):
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def write_glb(path: Path, positions, uvs=None, colors=None, png=None):
    """A minimal GLB of one triangle list (three vertices per face, no sharing): POSITION,
    TEXCOORD_0 (glTF's v points down: 1 - v of MeshLab's wedge coordinates) and the PNG as
    the base colour texture, or COLOR_0 (linear; `colors` are sRGB in [0, 1])."""
    n = len(positions)
    pos = np.asarray(positions, dtype=np.float32).reshape(n, 3)
    chunks, views, accessors = [], [], []

    def add(data: bytes, target=None):
        offset = sum(len(c) for c in chunks)
        chunks.append(data + b"\0" * ((4 - len(data) % 4) % 4))
        view = {"buffer": 0, "byteOffset": offset, "byteLength": len(data)}
        if target:
            view["target"] = target
        views.append(view)
        return len(views) - 1

    def accessor(arr, kind, minmax=False):
        v = add(arr.tobytes(), 34962)
        a = {"bufferView": v, "componentType": 5126, "count": len(arr), "type": kind}
        if minmax:
            a["min"] = arr.min(axis=0).tolist()
            a["max"] = arr.max(axis=0).tolist()
        accessors.append(a)
        return len(accessors) - 1

    attributes = {"POSITION": accessor(pos, "VEC3", True)}
    gltf = {"asset": {"version": "2.0", "generator": "fresco meshlab_texture.py"}}
    material = {"pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": 1.0}}
    if uvs is not None:
        uv = np.asarray(uvs, dtype=np.float32).reshape(n, 2).copy()
        uv[:, 1] = 1.0 - uv[:, 1]
        attributes["TEXCOORD_0"] = accessor(uv, "VEC2")
        image_view = add(png)
        gltf["images"] = [{"bufferView": image_view, "mimeType": "image/png"}]
        gltf["samplers"] = [{"magFilter": 9729, "minFilter": 9987, "wrapS": 33071, "wrapT": 33071}]
        gltf["textures"] = [{"sampler": 0, "source": 0}]
        material["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0}
    if colors is not None:
        col = srgb_to_linear(np.asarray(colors).reshape(n, 3)).astype(np.float32)
        attributes["COLOR_0"] = accessor(col, "VEC3")
    gltf["materials"] = [material]
    gltf["meshes"] = [{"primitives": [{"attributes": attributes, "material": 0, "mode": 4}]}]
    gltf["nodes"] = [{"mesh": 0}]
    gltf["scenes"] = [{"nodes": [0]}]
    gltf["scene"] = 0
    gltf["bufferViews"] = views
    gltf["accessors"] = accessors
    binary = b"".join(chunks)
    gltf["buffers"] = [{"byteLength": len(binary)}]
    js = json.dumps(gltf, separators=(",", ":")).encode()
    js += b" " * ((4 - len(js) % 4) % 4)
    total = 12 + 8 + len(js) + 8 + len(binary)
    tmp = path.with_suffix(".glb.tmp")
    with open(tmp, "wb") as f:
        f.write(struct.pack("<III", 0x46546C67, 2, total))
        f.write(struct.pack("<II", len(js), 0x4E4F534A) + js)
        f.write(struct.pack("<II", len(binary), 0x004E4942) + binary)
    os.replace(tmp, path)


def cpu_seconds():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def load(bundle, lst, mesh_path):
    """A MeshSet holding the rasters (Bundler project) and the mesh, the mesh current."""
    ms = pymeshlab.MeshSet()
    ms.load_project([str(bundle), str(lst)])
    ms.load_new_mesh(str(mesh_path))
    return ms


def corner_arrays(m):
    faces = m.face_matrix()
    return m.vertex_matrix()[faces.reshape(-1)], faces


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--colmap", type=Path, required=True)
    ap.add_argument("--images", type=Path, required=True)
    ap.add_argument("--mesh", type=Path, required=True)
    ap.add_argument("--exclude", default="")
    ap.add_argument("--texture-size", type=int, default=2048)
    ap.add_argument("-o", "--output", type=Path, required=True)
    ap.add_argument("--only", default="param,project,vertex")
    a = ap.parse_args()
    excluded = {s for s in a.exclude.split(",") if s}
    cameras, images = read_colmap_text(a.colmap)
    unknown = excluded - {i[0] for i in images}
    if unknown:
        sys.exit(f"--exclude names images the model does not have: {sorted(unknown)}")
    images = [i for i in images if i[0] not in excluded]
    a.output.mkdir(parents=True, exist_ok=True)
    work = a.output / "meshlab_work"
    work.mkdir(exist_ok=True)
    bundle, lst = write_bundler(cameras, images, a.images, work)
    # MeshLab writes a filter's texture next to the mesh file: work on a copy, never beside
    # the input; the copy keeps no vertex colours (a synthetic mesh carries its true albedo,
    # which a filter would otherwise keep where no raster sees a vertex).
    mesh_copy = work / "mesh.ply"
    strip = pymeshlab.MeshSet()
    strip.load_new_mesh(str(a.mesh))
    strip.save_current_mesh(str(mesh_copy), save_vertex_color=False, save_face_color=False)
    results = {"rasters": len(images), "texture_size": a.texture_size}
    only = set(a.only.split(","))

    if "param" in only or "project" in only:
        ms = load(bundle, lst, mesh_copy)
        if ms.raster_number() != len(images):
            sys.exit(f"MeshLab loaded {ms.raster_number()} rasters of {len(images)}")
        t, c = time.perf_counter(), cpu_seconds()
        ms.compute_texcoord_parametrization_and_texture_from_registered_rasters(
            texturesize=a.texture_size, texturename="meshlab_param.png"
        )
        results["param"] = {"wall_s": time.perf_counter() - t, "cpu_s": cpu_seconds() - c}
        m = ms.current_mesh()
        ms.save_current_mesh(str(work / "param.obj"), save_textures=True)
        png_path = work / "meshlab_param.png"
        if not png_path.is_file():
            sys.exit(f"the param filter wrote no {png_path}")
        shutil.copy(png_path, a.output / "meshlab_param.png")
        pos, faces = corner_arrays(m)
        uv = m.wedge_tex_coord_matrix()
        results["param"]["faces"] = int(len(faces))
        write_glb(a.output / "meshlab_param.glb", pos, uvs=uv, png=png_path.read_bytes())
        if "project" in only:
            t, c = time.perf_counter(), cpu_seconds()
            ms.compute_color_and_texture_from_active_rasters_projection(
                textname="meshlab_project.png", texsize=a.texture_size
            )
            results["project"] = {"wall_s": time.perf_counter() - t, "cpu_s": cpu_seconds() - c}
            ms.save_current_mesh(str(work / "project.obj"), save_textures=True)
            proj_png = work / "meshlab_project.png"
            if not proj_png.is_file():
                sys.exit(f"the project filter wrote no {proj_png}")
            write_glb(a.output / "meshlab_project.glb", pos, uvs=uv, png=proj_png.read_bytes())

    if "vertex" in only:
        ms = load(bundle, lst, mesh_copy)
        t, c = time.perf_counter(), cpu_seconds()
        ms.compute_color_from_active_rasters_projection()
        results["vertex"] = {"wall_s": time.perf_counter() - t, "cpu_s": cpu_seconds() - c}
        m = ms.current_mesh()
        pos, faces = corner_arrays(m)
        col = m.vertex_color_matrix()[faces.reshape(-1), :3]
        write_glb(a.output / "meshlab_vertex.glb", pos, colors=col)

    (a.output / "meshlab.json").write_text(json.dumps(results, indent=1) + "\n")
    print(json.dumps(results))


if __name__ == "__main__":
    main()
