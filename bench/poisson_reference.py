"""Helpers for bench/poisson.sh (issue 5): Open3D's screened Poisson on an oriented cloud,
and the symmetric Chamfer distance of a mesh to the ground-truth mesh.

    poisson_reference.py open3d <cloud.ply> <depth> <mesh_out.ply>   -> one JSON line
    poisson_reference.py chamfer <mesh.ply> <gt.ply>                 -> one JSON line

Chamfer: mean of the two one-sided mean distances, each from 100k area-uniform samples of
one mesh to the other mesh's surface (exact point-to-triangle distances with Open3D's
RaycastingScene), divided by the ground truth's bounding-box diagonal.
"""
import json
import sys
import time

import numpy as np
import open3d as o3d


def run_open3d(cloud, depth, out):
    pcd = o3d.io.read_point_cloud(cloud)
    t = time.perf_counter()
    mesh, _dens = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(
        pcd, depth=depth, n_threads=2)
    seconds = time.perf_counter() - t
    o3d.io.write_triangle_mesh(out, mesh)
    print(json.dumps({"tool": "open3d", "depth": depth, "seconds": seconds,
                      "vertices": len(mesh.vertices), "faces": len(mesh.triangles)}))


def one_sided(src, dst, n=100_000):
    pts = src.sample_points_uniformly(number_of_points=n, use_triangle_normal=False)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(dst))
    q = o3d.core.Tensor(np.asarray(pts.points), dtype=o3d.core.Dtype.Float32)
    return float(scene.compute_distance(q).numpy().mean())


def chamfer(mesh_path, gt_path):
    mesh = o3d.io.read_triangle_mesh(mesh_path)
    gt = o3d.io.read_triangle_mesh(gt_path)
    diag = float(np.linalg.norm(gt.get_max_bound() - gt.get_min_bound()))
    d = 0.5 * (one_sided(mesh, gt) + one_sided(gt, mesh))
    print(json.dumps({"mesh": mesh_path, "chamfer": d, "chamfer_fraction": d / diag}))


if __name__ == "__main__":
    if sys.argv[1] == "open3d":
        run_open3d(sys.argv[2], int(sys.argv[3]), sys.argv[4])
    elif sys.argv[1] == "chamfer":
        chamfer(sys.argv[2], sys.argv[3])
    else:
        sys.exit(f"unknown command {sys.argv[1]}")
