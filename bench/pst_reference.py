"""Reference for bench/pst.sh: Open3D 0.20 reads the vertices of the same PLY into memory
(read_point_cloud) and reduces them with a voxel grid (voxel_down_sample, one averaged point
per occupied voxel: uniform clustering, the in-core analogue of fresco's alpha = 0 sampling).
The voxel size is first searched (untimed) so that the output has about n points; then one
read and one down-sampling are timed. Prints one JSON line.

    python bench/pst_reference.py <mesh.ply> <n>
"""
import json
import resource
import sys
import time

import numpy as np
import open3d as o3d

path, n = sys.argv[1], int(sys.argv[2])
def cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


t0, c0 = time.perf_counter(), cpu()
pcd = o3d.io.read_point_cloud(path)
read_s, read_cpu = time.perf_counter() - t0, cpu() - c0
pts = len(pcd.points)
lo, hi = pcd.get_min_bound(), pcd.get_max_bound()
diag = float(np.linalg.norm(hi - lo))
# A surface sampled at spacing h has about area / h^2 points: count(h) ~ 1/h^2. Secant steps
# on that law, at most 6 (untimed).
h = diag / np.sqrt(n)
for _ in range(6):
    got = len(pcd.voxel_down_sample(h).points)
    if abs(got - n) <= 0.01 * n:
        break
    h *= np.sqrt(got / n)
t0, c0 = time.perf_counter(), cpu()
down = pcd.voxel_down_sample(h)
down_s, down_cpu = time.perf_counter() - t0, cpu() - c0
print(json.dumps({
    "tool": "open3d",
    "input_points": pts,
    "samples": len(down.points),
    "voxel": h,
    "read_s": read_s,
    "downsample_s": down_s,
    "seconds": read_s + down_s,
    "cpu_s": read_cpu + down_cpu,
    "peak_rss_kb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
}))
