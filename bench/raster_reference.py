"""Reference for bench/raster.sh: Open3D's RaycastingScene (Embree BVH) casting one ray per
pixel centre of the same 1M-triangle torus and 1920x1080 camera as
datasets/examples/raster_bench.rs, giving depth and the visible triangle per pixel like
fresco's raster::visibility. Prints one JSON line per run."""

import json
import sys
import time

import numpy as np
import open3d as o3d


def torus(major, minor, nu, nv):
    # Same vertex order and faces as fresco_datasets::shapes::torus.
    u = 2 * np.pi * np.arange(nu) / nu
    v = 2 * np.pi * np.arange(nv) / nv
    uu, vv = np.meshgrid(u, v, indexing="ij")
    ring = major + minor * np.cos(vv)
    pos = np.stack([ring * np.cos(uu), ring * np.sin(uu), minor * np.sin(vv)], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    idx = lambda a, b: (a % nu) * nv + (b % nv)
    a, b, c, d = idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)
    faces = np.stack([np.stack([a, b, c], -1), np.stack([a, c, d], -1)], 2).reshape(-1, 3)
    return pos, faces


def main():
    runs = int(sys.argv[1]) if len(sys.argv) > 1 else 5
    pos, faces = torus(0.7, 0.3, 1000, 500)
    w, h, f = 1920, 1080, 1400.0
    # Ray through pixel (x, y) leaves at (x + 0.5, y + 0.5) in fresco's (COLMAP's) convention.
    xs, ys = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    theta = np.radians(-130.0)
    rot = np.array([[1, 0, 0], [0, np.cos(theta), -np.sin(theta)], [0, np.sin(theta), np.cos(theta)]])
    t = np.array([0.0, 0.0, 2.2])
    dirs_cam = np.stack([(xs - 960.0) / f, (ys - 540.0) / f, np.ones_like(xs)], -1).reshape(-1, 3)
    # World from camera: centre -R^T t, directions R^T d.
    centre = -rot.T @ t
    dirs = dirs_cam @ rot  # row vectors: (R^T d)^T = d^T R
    rays = np.concatenate([np.broadcast_to(centre, dirs.shape), dirs], 1).astype(np.float32)
    rays_t = o3d.core.Tensor(rays)
    for run in range(runs):
        t0 = time.perf_counter()
        scene = o3d.t.geometry.RaycastingScene()
        mesh = o3d.t.geometry.TriangleMesh()
        mesh.vertex.positions = o3d.core.Tensor(pos.astype(np.float32))
        mesh.triangle.indices = o3d.core.Tensor(faces.astype(np.int32))
        scene.add_triangles(mesh)
        t1 = time.perf_counter()
        ans = scene.cast_rays(rays_t)
        hit = ans["t_hit"].numpy()
        ids = ans["primitive_ids"].numpy()
        t2 = time.perf_counter()
        covered = int(np.isfinite(hit).sum())
        print(json.dumps({
            "tool": "open3d", "run": run, "triangles": len(faces), "pixels": w * h,
            "covered_pixels": covered, "build_s": round(t1 - t0, 4),
            "cast_s": round(t2 - t1, 4), "total_s": round(t2 - t0, 4),
        }), flush=True)


if __name__ == "__main__":
    main()
