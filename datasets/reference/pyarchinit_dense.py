#!/usr/bin/env python3
"""CPU PatchMatch reference for fresco's dense stage (issue 13, "Side by side in one run").

COLMAP's own patch_match_stereo needs CUDA; the one CPU PatchMatch that installs from PyPI here
is pyarchinit-photogrammetry-core 0.5.0 (`ppg_core.patchmatch_depth`, Rust). This script
wraps it in COLMAP's CPU pieces so that only the depth maps come from pyarchinit:

1. undistortion: `pycolmap.undistort_images` (pinhole cameras, COLMAP's image_undistorter,
   default options) into a COLMAP dense workspace `<out>/workspace`;
2. source views: for each reference view, the views sharing the most sparse 3D points whose
   triangulation angle with the reference is at least MIN_TRI_ANGLE_DEG (COLMAP's auto source
   selection works from the same shared-point counts), at most SOURCES of them; depth range from
   the 1st / 99th percentile of the sparse points' depths, stretched by 0.75 / 1.25 (COLMAP's
   ComputeDepthRanges);
3. PatchMatch: `ppg_core.patchmatch_depth` per view on the undistorted grey image, with the
   package's own defaults except where noted (PM below): random initial planes in the depth range,
   ITERATIONS red-black sweeps, NCC over a (2*half_window+1)^2 window sampled every `step`
   pixels, cost from the best `top_k` sources, pixels with cost above `max_cost` dropped;
   normals turned to face the camera (COLMAP's convention);
4. written as COLMAP depth / normal maps (`stereo/depth_maps/NAME.photometric.bin`,
   `stereo/normal_maps/NAME.photometric.bin`: there is no geometric-consistency pass, so they
   are photometric maps) and fused with `pycolmap.stereo_fusion(input_type="photometric")`
   with COLMAP's default StereoFusionOptions (min 5 pixels, 2 px, 1% depth, 10 degrees);
5. `<out>/fused.ply` (the fused points) and `<out>/timing.json` (per-stage wall and CPU
   seconds, settings, versions, point count).

Judge the cloud with fresco's judge, the one the fresco figures use:
    target/release/examples/dense_synth <dataset> <out> --eval-only

Usage (from the repository root):
    python3 -m venv datasets/reference/.venv-dense
    datasets/reference/.venv-dense/bin/pip install -r datasets/reference/requirements-dense.txt
    fresco synth temple --views 24 --size 640x480 -o T
    nice -n 5 datasets/reference/.venv-dense/bin/python datasets/reference/pyarchinit_dense.py T OUT
Options: --sources N (default 6: the low end of COLMAP's and OpenMVS's 6-8, and the
setting of the committed run; about 36 CPU-s a view at 640x480), --iterations N (default 4),
--views a,b (only these reference views, for a quick look; fusion runs on what was computed).
"""
import argparse
import json
import os
import platform
import resource
import shutil
import sys
import time
from pathlib import Path

import numpy as np

try:
    import ppg_core
    import pycolmap
except ImportError as e:  # pragma: no cover - a clear message instead of a traceback
    sys.exit(
        f"pyarchinit_dense.py: {e}; install datasets/reference/requirements-dense.txt "
        "into a venv (see the docstring)"
    )

SOURCES = 6
ITERATIONS = 4
MIN_TRI_ANGLE_DEG = 1.0
# ppg_core.patchmatch_depth's keyword defaults in 0.5.0, written out so the run records them.
PM = dict(half_window=4, step=2, top_k=3, max_cost=0.6, seed=1, min_views=2)


def cpu_seconds():
    r = resource.getrusage(resource.RUSAGE_SELF)
    c = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime + c.ru_utime + c.ru_stime


class Stage:
    """Wall and CPU seconds of one stage, printed and kept."""

    def __init__(self, name, timings):
        self.name, self.timings = name, timings

    def __enter__(self):
        self.w0, self.c0 = time.time(), cpu_seconds()
        return self

    def __exit__(self, *exc):
        wall, cpu = time.time() - self.w0, cpu_seconds() - self.c0
        self.timings[self.name] = {"wall_s": round(wall, 2), "cpu_s": round(cpu, 2)}
        print(f"[{self.name}] {wall:.1f} s wall, {cpu:.1f} CPU-s", flush=True)


def load_model(path):
    if not path.is_dir():
        sys.exit(f"pyarchinit_dense.py: no sparse model folder {path}")
    try:
        return pycolmap.Reconstruction(str(path))
    except Exception as e:  # pycolmap raises plain RuntimeErrors
        sys.exit(f"pyarchinit_dense.py: cannot read the COLMAP model {path}: {e}")


def pose(image):
    T = image.cam_from_world()
    return np.asarray(T.rotation.matrix(), dtype=np.float64), np.asarray(T.translation, dtype=np.float64)


def centre(image):
    R, t = pose(image)
    return -R.T @ t


def select_sources(rec, max_sources):
    """Per image id: (sources, (depth_min, depth_max)) from the sparse points."""
    ids = sorted(rec.images)
    centres = {i: centre(rec.images[i]) for i in ids}
    seen = {i: set() for i in ids}
    for pid, p in rec.points3D.items():
        for el in p.track.elements:
            seen[el.image_id].add(pid)
    out = {}
    min_sin = np.sin(np.radians(MIN_TRI_ANGLE_DEG))
    for i in ids:
        R, t = pose(rec.images[i])
        pts = np.array([rec.points3D[p].xyz for p in seen[i]])
        if len(pts) == 0:
            out[i] = ([], None)
            continue
        depths = (pts @ R.T + t)[:, 2]
        depths = depths[depths > 0]
        d_min = np.percentile(depths, 1) * 0.75
        d_max = np.percentile(depths, 99) * 1.25
        scores = []
        for j in ids:
            if j == i:
                continue
            shared = seen[i] & seen[j]
            if not shared:
                continue
            xyz = np.array([rec.points3D[p].xyz for p in shared])
            a = xyz - centres[i]
            b = xyz - centres[j]
            cosang = np.sum(a * b, 1) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
            sinang = np.sqrt(np.clip(1 - cosang**2, 0, 1))
            good = int(np.sum(sinang >= min_sin))
            if good > 0:
                scores.append((good, j))
        scores.sort(key=lambda s: (-s[0], s[1]))
        out[i] = ([j for _, j in scores[:max_sources]], (float(d_min), float(d_max)))
    return out


def grey(path):
    bmp = pycolmap.Bitmap.read(str(path), False)
    if bmp is None:
        sys.exit(f"pyarchinit_dense.py: cannot read image {path}")
    a = np.asarray(bmp.to_array(), dtype=np.float32)
    if a.ndim == 3:
        a = a[..., 0]
    return np.ascontiguousarray(a / 255.0, dtype=np.float32)


def k_of(camera):
    """(fx, fy, cx, cy) with the centre of the first pixel at 0 (COLMAP puts it at 0.5)."""
    if camera.model.name != "PINHOLE":
        sys.exit(f"pyarchinit_dense.py: undistorted camera is {camera.model.name}, not PINHOLE")
    fx, fy, cx, cy = camera.params
    return (float(fx), float(fy), float(cx) - 0.5, float(cy) - 0.5)


def write_colmap_mat(path, array):
    """COLMAP's mvs Mat format: `width&height&channels&` then float32, channel-major rows."""
    a = np.asarray(array, dtype=np.float32)
    if a.ndim == 2:
        a = a[..., None]
    h, w, c = a.shape
    tmp = Path(str(path) + ".tmp")
    with open(tmp, "wb") as f:
        f.write(f"{w}&{h}&{c}&".encode())
        f.write(np.ascontiguousarray(a.transpose(2, 0, 1)).astype("<f4").tobytes())
    os.replace(tmp, path)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset", type=Path, help="dataset written by `fresco synth` (sparse/, images/)")
    ap.add_argument("out", type=Path, help="output folder (workspace/, fused.ply, timing.json)")
    ap.add_argument("--sources", type=int, default=SOURCES)
    ap.add_argument("--iterations", type=int, default=ITERATIONS)
    ap.add_argument("--views", default="", help="comma-separated image names (default: all)")
    args = ap.parse_args()

    sparse, images = args.dataset / "sparse", args.dataset / "images"
    if not images.is_dir():
        sys.exit(f"pyarchinit_dense.py: no image folder {images}")
    load_model(sparse)  # a clear error before the undistorter's
    ws = args.out / "workspace"
    if ws.exists():
        shutil.rmtree(ws)
    args.out.mkdir(parents=True, exist_ok=True)
    timings = {}
    load_start = list(os.getloadavg())
    t_all, c_all = time.time(), cpu_seconds()

    with Stage("undistort", timings):
        pycolmap.undistort_images(str(ws), str(sparse), str(images), output_type="COLMAP")
    rec = load_model(ws / "sparse")
    if len(rec.points3D) == 0:
        sys.exit(f"pyarchinit_dense.py: the model {sparse} has no 3D points (no depth range)")

    with Stage("source_selection", timings):
        plan = select_sources(rec, args.sources)

    wanted = set(filter(None, args.views.split(",")))
    names = {i: rec.images[i].name for i in rec.images}
    per_view = []
    greys = {}

    def grey_of(i):
        if i not in greys:
            greys[i] = grey(ws / "images" / names[i])
        return greys[i]

    depth_dir, normal_dir = ws / "stereo" / "depth_maps", ws / "stereo" / "normal_maps"
    with Stage("patch_match", timings):
        for i in sorted(rec.images, key=lambda i: names[i]):
            if wanted and names[i] not in wanted:
                continue
            srcs, drange = plan[i]
            if len(srcs) < PM["min_views"]:
                print(f"warning: {names[i]}: {len(srcs)} source views, skipped", file=sys.stderr)
                continue
            w0, c0 = time.time(), cpu_seconds()
            ref = rec.images[i]
            R_r, t_r = pose(ref)
            sources = []
            for j in srcs:
                R_s, t_s = pose(rec.images[j])
                R = R_s @ R_r.T
                t = t_s - R @ t_r
                sources.append((grey_of(j), k_of(rec.images[j].camera), R, t))
            k = k_of(ref.camera)
            depth, normals, cost = ppg_core.patchmatch_depth(
                grey_of(i), k, sources, drange, iterations=args.iterations, **PM
            )
            depth = np.asarray(depth, dtype=np.float32)
            normals = np.asarray(normals, dtype=np.float32)
            # Normals facing the camera, as COLMAP's depth-map fusion expects.
            h, w = depth.shape
            u, v = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
            ray = np.stack([(u - k[2]) / k[0], (v - k[3]) / k[1], np.ones_like(u)], -1)
            flip = np.sum(normals * ray, -1) > 0
            normals[flip] *= -1
            normals[depth <= 0] = 0
            write_colmap_mat(depth_dir / f"{names[i]}.photometric.bin", depth)
            write_colmap_mat(normal_dir / f"{names[i]}.photometric.bin", normals)
            # Sanity check: depth at the sparse points this view sees, against their depth.
            ratios = []
            for p2 in ref.points2D:
                if p2.has_point3D():
                    x, y = p2.xy
                    c, r = int(x), int(y)
                    if 0 <= r < h and 0 <= c < w and depth[r, c] > 0:
                        z = (R_r @ rec.points3D[p2.point3D_id].xyz + t_r)[2]
                        ratios.append(depth[r, c] / z)
            valid = float(np.mean(depth > 0))
            wall, cpu = time.time() - w0, cpu_seconds() - c0
            med = float(np.median(ratios)) if ratios else float("nan")
            print(
                f"{names[i]}: {len(srcs)} sources, depth {drange[0]:.3f}-{drange[1]:.3f}, "
                f"valid {valid:.3f}, depth/sparse median {med:.4f}, {wall:.1f} s, {cpu:.1f} CPU-s",
                flush=True,
            )
            per_view.append(
                {"name": names[i], "sources": [names[j] for j in srcs], "valid": round(valid, 4),
                 "depth_over_sparse_median": round(med, 4), "wall_s": round(wall, 2),
                 "cpu_s": round(cpu, 2)}
            )
    if not per_view:
        sys.exit("pyarchinit_dense.py: no depth map was computed")

    fusion_options = pycolmap.StereoFusionOptions()  # COLMAP's defaults
    fused = args.out / "fused.ply"
    with Stage("fusion", timings):
        fused_rec = pycolmap.stereo_fusion(
            str(fused), str(ws), input_type="photometric", options=fusion_options,
            output_type="ply",
        )
    points = len(fused_rec.points3D) if fused_rec is not None else None
    timings["total"] = {"wall_s": round(time.time() - t_all, 2), "cpu_s": round(cpu_seconds() - c_all, 2)}
    print(f"[total] {timings['total']['wall_s']} s wall, {timings['total']['cpu_s']} CPU-s, {points} points")
    report = {
        "tool": "pyarchinit-photogrammetry-core (ppg_core.patchmatch_depth) + pycolmap undistortion and stereo_fusion",
        "versions": {"ppg_core": "0.5.0", "pycolmap": pycolmap.__version__, "numpy": np.__version__,
                     "python": platform.python_version()},
        "dataset": args.dataset.name,
        "settings": {"sources": args.sources, "iterations": args.iterations, "min_tri_angle_deg": MIN_TRI_ANGLE_DEG,
                     "depth_range": "1st/99th percentile of the sparse depths x 0.75 / 1.25",
                     "patchmatch": PM, "fusion": "pycolmap.StereoFusionOptions() defaults, input_type=photometric",
                     "undistortion": "pycolmap.undistort_images defaults (PINHOLE)"},
        "points": points,
        "views": len(per_view),
        "timings": timings,
        "per_view": per_view,
        "cpu_count": os.cpu_count(),
        "load_average_at_start": load_start,
        "load_average_at_end": list(os.getloadavg()),
    }
    (args.out / "timing.json").write_text(json.dumps(report, indent=2) + "\n")


if __name__ == "__main__":
    main()
