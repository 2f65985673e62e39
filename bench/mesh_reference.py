#!/usr/bin/env python3
"""Open3D references for bench/mesh.sh (issue 5).

    mesh_reference.py mesh <cloud.ply> <out.ply> <depth> <faces>
        Open3D's counterpart of `fresco mesh`: create_from_point_cloud_poisson (PoissonRecon
        inside; n_threads=2, its defaults otherwise), density trimming at one below the
        median vertex density (Open3D returns PoissonRecon's per-vertex density, a depth on
        the same log4 scale as fresco's: the same rule as `fresco mesh`'s default), then
        simplify_quadric_decimation to <faces> (0: none). One JSON line with the time of the
        chain (reading and writing excluded, as for fresco's figure).

    mesh_reference.py decimate <in.ply> <out.ply> <faces>
        simplify_quadric_decimation alone; one JSON line with its time.
"""
import json
import sys
import time

import numpy as np
import open3d as o3d


def mesh(cloud_path, out_path, depth, faces):
    pcd = o3d.io.read_point_cloud(cloud_path)
    if not pcd.has_normals():
        sys.exit(f"{cloud_path}: no normals")
    t = time.perf_counter()
    m, density = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(
        pcd, depth=depth, n_threads=2)
    t_poisson = time.perf_counter() - t
    # PoissonRecon's per-vertex density is a depth (log4 of the sample count per node, 7.78
    # median for 200k points on the sphere, where fresco's is 7.8): the same scale.
    density = np.asarray(density)
    threshold = float(np.median(density) - 1.0)
    m.remove_vertices_by_mask(density < threshold)
    poisson_faces = len(m.triangles)
    if faces > 0 and len(m.triangles) > faces:
        m = m.simplify_quadric_decimation(target_number_of_triangles=faces)
    seconds = time.perf_counter() - t
    o3d.io.write_triangle_mesh(out_path, m)
    print(json.dumps({
        "tool": "open3d", "version": o3d.__version__, "seconds": seconds,
        "seconds_poisson": t_poisson, "faces_after_trim": poisson_faces,
        "faces": len(m.triangles),
    }))


def decimate(in_path, out_path, faces):
    m = o3d.io.read_triangle_mesh(in_path)
    before = len(m.triangles)
    t = time.perf_counter()
    out = m.simplify_quadric_decimation(target_number_of_triangles=faces)
    seconds = time.perf_counter() - t
    o3d.io.write_triangle_mesh(out_path, out)
    print(json.dumps({"tool": "open3d", "seconds": seconds, "faces_before": before,
                      "faces_after": len(out.triangles)}))


if __name__ == "__main__":
    if sys.argv[1] == "mesh":
        mesh(sys.argv[2], sys.argv[3], int(sys.argv[4]), int(sys.argv[5]))
    elif sys.argv[1] == "decimate":
        decimate(sys.argv[2], sys.argv[3], int(sys.argv[4]))
    else:
        sys.exit(f"unknown command {sys.argv[1]}")
