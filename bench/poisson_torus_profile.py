"""Where a reconstruction of bench/poisson.sh's torus (R 0.7, r 0.3 around z) departs from
the ground-truth mesh: signed distances of 200k area samples of the reconstruction to the
ground truth's facets (Open3D RaycastingScene, negative inside), overall and by the angle
around the tube (0 deg: outer equator, positive Gaussian curvature; +-90: top and bottom,
normal along z, where the surface is parallel to the lattice planes; 180: inner equator,
negative Gaussian curvature), and the other side (ground-truth samples to the mesh).

    poisson_torus_profile.py <torus_gt.ply> <mesh.ply> [<mesh.ply> ...]
"""
import sys

import numpy as np
import open3d as o3d

R, r = 0.7, 0.3


def scene_of(mesh):
    s = o3d.t.geometry.RaycastingScene()
    s.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
    return s


def tube_angle(p):
    return np.arctan2(p[:, 2], np.hypot(p[:, 0], p[:, 1]) - R)


def main():
    gt = o3d.io.read_triangle_mesh(sys.argv[1])
    gt_scene = scene_of(gt)
    diag = float(np.linalg.norm(gt.get_max_bound() - gt.get_min_bound()))
    np.random.seed(0)
    gp = np.asarray(gt.sample_points_uniformly(200_000).points)
    bins = np.linspace(-np.pi, np.pi, 13)
    for path in sys.argv[2:]:
        m = o3d.io.read_triangle_mesh(path)
        pts = np.asarray(m.sample_points_uniformly(200_000).points)
        sd = gt_scene.compute_signed_distance(
            o3d.core.Tensor(pts, dtype=o3d.core.Dtype.Float32)).numpy()
        back = scene_of(m).compute_distance(
            o3d.core.Tensor(gp, dtype=o3d.core.Dtype.Float32)).numpy()
        chamfer = 0.5 * (np.abs(sd).mean() + back.mean())
        print(f"{path}: Chamfer {100 * chamfer / diag:.5f}% of the diagonal; signed distance "
              f"to the facets mean {sd.mean():+.2e} std {sd.std():.2e}")
        print("| tube angle deg | signed mean | signed std | mean abs | GT to mesh |")
        print("|---|---|---|---|---|")
        v, vg = np.digitize(tube_angle(pts), bins) - 1, np.digitize(tube_angle(gp), bins) - 1
        for b in range(12):
            s, g = v == b, vg == b
            print(f"| {np.degrees(0.5 * (bins[b] + bins[b + 1])):+.0f} | {sd[s].mean():+.2e} | "
                  f"{sd[s].std():.2e} | {np.abs(sd[s]).mean():.2e} | {back[g].mean():.2e} |")


if __name__ == "__main__":
    main()
