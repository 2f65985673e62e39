#!/usr/bin/env python3
"""Resample a pinhole photo set to one focal length and a centred principal point.

MeshLab's raster import (a Bundler project, datasets/reference/meshlab_texture.py) takes one
focal length per camera and the principal point at the image centre; the Middlebury cameras
of templeSparseRing have fx != fy and a principal point 18 px off centre, so MeshLab cannot
be run on them as they are. For a pinhole camera a change of intrinsics with the pose kept is
an exact homography of the image, H = K_new K_old^-1: each output pixel looks along the same
ray as the input point it is read from. This script writes such a set: every photo warped
(bilinear, pixels outside the input black) to f = sqrt(fx fy), principal point (w/2, h/2),
and the COLMAP text model with those cameras and the same poses and points. Every method is
then scored on the warped set, so all of them see the same photos.

Usage: recentre_pinhole.py --colmap <text model dir> --images <dir> -o <out dir>
Writes <out>/sparse/{cameras,images,points3D}.txt and <out>/images/<name>.
"""

import argparse
import shutil
import sys
from pathlib import Path

import numpy as np
from PIL import Image


def read_cameras(path: Path):
    cams = {}
    for line in path.read_text().splitlines():
        if not line.strip() or line.startswith("#"):
            continue
        t = line.split()
        cams[int(t[0])] = (t[1], int(t[2]), int(t[3]), [float(x) for x in t[4:]])
    return cams


def intrinsics(cam_id, cam):
    """(fx, fy, cx, cy) of a distortion-free COLMAP camera, or SystemExit naming it."""
    model, _, _, p = cam
    if model == "PINHOLE":
        return p[0], p[1], p[2], p[3]
    if model == "SIMPLE_PINHOLE":
        return p[0], p[0], p[1], p[2]
    sys.exit(f"camera {cam_id}: model {model} is not a distortion-free pinhole")


def image_cameras(path: Path):
    """Image name -> camera id from a COLMAP images.txt (every other line is points)."""
    lines = [l for l in path.read_text().splitlines() if not l.startswith("#")]
    out = {}
    for header in lines[0::2]:
        t = header.split()
        if len(t) >= 10:
            out[t[9]] = int(t[8])
    return out


def warp(photo: np.ndarray, fx, fy, cx, cy, f, ncx, ncy) -> np.ndarray:
    """Bilinear resampling of `photo` (h x w x c) from intrinsics (fx, fy, cx, cy) to
    (f, f, ncx, ncy); COLMAP's convention: pixel (i, j) has its centre at (i + 0.5, j + 0.5)."""
    h, w = photo.shape[:2]
    u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    su = fx * (u - ncx) / f + cx - 0.5
    sv = fy * (v - ncy) / f + cy - 0.5
    x0, y0 = np.floor(su).astype(int), np.floor(sv).astype(int)
    ax, ay = (su - x0)[..., None], (sv - y0)[..., None]
    src = photo.astype(np.float64)
    out = np.zeros_like(src)
    for dx, dy, wt in [(0, 0, (1 - ax) * (1 - ay)), (1, 0, ax * (1 - ay)),
                       (0, 1, (1 - ax) * ay), (1, 1, ax * ay)]:
        xi, yi = x0 + dx, y0 + dy
        ok = (xi >= 0) & (xi < w) & (yi >= 0) & (yi < h)
        sample = np.zeros_like(src)
        sample[ok] = src[yi[ok], xi[ok]]
        out += wt * sample
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--colmap", type=Path, required=True)
    ap.add_argument("--images", type=Path, required=True)
    ap.add_argument("-o", "--out", type=Path, required=True)
    a = ap.parse_args()
    cams = read_cameras(a.colmap / "cameras.txt")
    if a.out.exists():
        sys.exit(f"{a.out}: exists; choose a new output directory")
    (a.out / "sparse").mkdir(parents=True)
    (a.out / "images").mkdir()
    new_cams = {}
    lines = ["# Camera list: CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[] (recentre_pinhole.py)"]
    for cam_id, cam in sorted(cams.items()):
        fx, fy, cx, cy = intrinsics(cam_id, cam)
        _, w, h, _ = cam
        f = float(np.sqrt(fx * fy))
        new_cams[cam_id] = (fx, fy, cx, cy, f, w / 2, h / 2)
        lines.append(f"{cam_id} SIMPLE_PINHOLE {w} {h} {f!r} {w / 2!r} {h / 2!r}")
    (a.out / "sparse" / "cameras.txt").write_text("\n".join(lines) + "\n")
    for name in ("images.txt", "points3D.txt"):
        shutil.copyfile(a.colmap / name, a.out / "sparse" / name)
    for name, cam_id in sorted(image_cameras(a.colmap / "images.txt").items()):
        src = a.images / name
        if not src.is_file():
            sys.exit(f"{src}: photo of the model missing")
        photo = np.asarray(Image.open(src).convert("RGB"))
        fx, fy, cx, cy, f, ncx, ncy = new_cams[cam_id]
        if photo.shape[1] != cams[cam_id][1] or photo.shape[0] != cams[cam_id][2]:
            sys.exit(f"{src}: {photo.shape[1]}x{photo.shape[0]}, camera {cam_id} says "
                     f"{cams[cam_id][1]}x{cams[cam_id][2]}")
        Image.fromarray(warp(photo, fx, fy, cx, cy, f, ncx, ncy)).save(a.out / "images" / name)
        print(f"{name}: f {f:.3f}, principal point ({cx}, {cy}) -> ({ncx}, {ncy})")


if __name__ == "__main__":
    main()
