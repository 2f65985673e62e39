#!/usr/bin/env python3
"""COLMAP reference models for the bundled photo sets (issue 4).

Runs pycolmap's default pipeline (SIFT extraction, exhaustive matching, incremental mapping)
on templeSparseRing and sceaux_castle (the 1600 px copy in datasets/), keeps the largest
model, and writes it as a COLMAP text model under datasets/reference/colmap/<set>/.
To keep the committed files small, images.txt keeps only the keypoints that observe a 3D
point (renumbered; the tracks in points3D.txt are renumbered to match), so the model is
still a valid COLMAP model: the script reads it back with pycolmap to check that.

Also writes datasets/reference/colmap/<set>/run.json with the pycolmap version, options,
timings and counts. The pose figures of the models are computed by `fresco eval poses`
(bench/sfm.sh and the tests read the committed models; CI has no pycolmap).

Usage: /work/venv/bin/python datasets/reference/colmap_reference.py [set ...]
"""
import json
import os
import resource
import shutil
import sys
import tempfile
import time
from pathlib import Path

import pycolmap

HERE = Path(__file__).resolve().parent
DATASETS = HERE.parent
SETS = {
    "templeSparseRing": DATASETS / "templeSparseRing",
    "sceaux_castle": DATASETS / "sceaux_castle" / "images",
}


def cpu_seconds():
    r = resource.getrusage(resource.RUSAGE_SELF)
    c = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime + c.ru_utime + c.ru_stime


def run(name, image_dir, out_dir):
    work = Path(tempfile.mkdtemp(prefix=f"colmap_{name}_"))
    db = work / "database.db"
    images = sorted(p.name for p in image_dir.iterdir() if p.suffix.lower() in (".png", ".jpg", ".jpeg"))
    timings = {}
    t0, c0 = time.time(), cpu_seconds()
    pycolmap.extract_features(db, image_dir, image_names=images, camera_mode=pycolmap.CameraMode.SINGLE)
    timings["extract"] = time.time() - t0
    t1 = time.time()
    pycolmap.match_exhaustive(db)
    timings["match"] = time.time() - t1
    t2 = time.time()
    models = pycolmap.incremental_mapping(db, image_dir, work / "sparse")
    timings["map"] = time.time() - t2
    timings["total_wall"] = time.time() - t0
    timings["total_cpu"] = cpu_seconds() - c0
    if not models:
        raise SystemExit(f"{name}: COLMAP built no model")
    best = max(models.values(), key=lambda r: r.num_reg_images())
    full = work / "full"
    full.mkdir()
    best.write_text(str(full))
    out_dir.mkdir(parents=True, exist_ok=True)
    compact_text_model(full, out_dir)
    # Check that COLMAP reads the committed model back and that it is the same model.
    back = pycolmap.Reconstruction(str(out_dir))
    assert back.num_reg_images() == best.num_reg_images(), "read-back image count differs"
    assert back.num_points3D() == best.num_points3D(), "read-back point count differs"
    info = {
        "set": name,
        "pycolmap": pycolmap.__version__,
        "images": len(images),
        "models": len(models),
        "registered": best.num_reg_images(),
        "points3D": best.num_points3D(),
        "mean_reprojection_error_px": best.compute_mean_reprojection_error(),
        "cameras": {str(cid): {"model": c.model.name, "params": list(c.params)} for cid, c in best.cameras.items()},
        "options": "pycolmap defaults: SIFT extraction (single camera), exhaustive matching, incremental mapping",
        "seconds": timings,
        "machine": "2-core shared development machine",
    }
    (out_dir / "run.json").write_text(json.dumps(info, indent=2) + "\n")
    shutil.rmtree(work)
    return info


def compact_text_model(src, dst):
    """Copies a COLMAP text model keeping only the keypoints with a 3D point."""
    shutil.copy(src / "cameras.txt", dst / "cameras.txt")
    remap = {}  # (image_id, old point2D idx) -> new idx
    lines = (src / "images.txt").read_text().splitlines()
    out = []
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.startswith("#") or not line.strip():
            if line.startswith("#") and "Number of images" in line:
                out.append(line.split(", mean observations")[0])
            elif line.startswith("#"):
                out.append(line)
            i += 1
            continue
        header = line
        image_id = int(header.split()[0])
        pts = lines[i + 1].split() if i + 1 < len(lines) else []
        kept = []
        for k in range(len(pts) // 3):
            x, y, pid = pts[3 * k], pts[3 * k + 1], int(pts[3 * k + 2])
            if pid != -1:
                remap[(image_id, k)] = len(kept)
                kept.append(f"{x} {y} {pid}")
        out.append(header)
        out.append(" ".join(kept))
        i += 2
    (dst / "images.txt").write_text("\n".join(out) + "\n")
    pout = []
    for line in (src / "points3D.txt").read_text().splitlines():
        if line.startswith("#") or not line.strip():
            pout.append(line)
            continue
        f = line.split()
        head, track = f[:8], f[8:]
        new = []
        for k in range(len(track) // 2):
            im, idx = int(track[2 * k]), int(track[2 * k + 1])
            new += [str(im), str(remap[(im, idx)])]
        pout.append(" ".join(head + new))
    (dst / "points3D.txt").write_text("\n".join(pout) + "\n")


def main():
    names = sys.argv[1:] or list(SETS)
    for name in names:
        info = run(name, SETS[name], HERE / "colmap" / name)
        print(json.dumps({k: info[k] for k in ("set", "registered", "points3D", "mean_reprojection_error_px", "seconds")}))


if __name__ == "__main__":
    main()
