#!/usr/bin/env python3
"""COLMAP on issue 18's no-EXIF narrow-field ring (the 4x focal hard case).

The scene is the hard-case test's (`sfm/tests/hard_cases.rs`): `fresco synth torus --views 16
--seed 3`, true focal length 4x fresco's default prior 1.2 max(w, h), rendered at 320x240 and
at 640x480. The photos carry no EXIF, so COLMAP starts from its own default prior as well.
This script renders both sets with the fresco binary given, runs pycolmap's default pipeline
(SIFT, exhaustive matching, incremental mapping; one SIMPLE_RADIAL camera, as fresco) and
writes, per size, the models, registered images, estimated focal length and its error
against the generator's to datasets/reference/colmap/hard_focal_4x.json, beside fresco's
figures, which the hard-case tests print.

Usage: <venv>/bin/python datasets/reference/colmap_hard_focal.py <fresco binary>
(the venv from bench/requirements.txt, which pins pycolmap).
"""
import json
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pycolmap

HERE = Path(__file__).resolve().parent
SIZES = [(320, 240), (640, 480)]


def cpu_seconds():
    r = resource.getrusage(resource.RUSAGE_SELF)
    c = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime + c.ru_utime + c.ru_stime


def run(fresco, width, height, work):
    true_focal = 4.0 * 1.2 * max(width, height)
    scene = work / f"torus_{width}"
    subprocess.run(
        [fresco, "synth", "torus", "--views", "16", "--seed", "3", "--size", f"{width}x{height}",
         "--focal", str(true_focal), "-o", str(scene)],
        check=True, stdout=subprocess.DEVNULL)
    images = scene / "images"
    db = work / f"db_{width}.db"
    reader = pycolmap.ImageReaderOptions()
    reader.camera_model = "SIMPLE_RADIAL"
    t0, c0 = time.time(), cpu_seconds()
    pycolmap.extract_features(db, images, camera_mode=pycolmap.CameraMode.SINGLE,
                              reader_options=reader)
    pycolmap.match_exhaustive(db)
    models = pycolmap.incremental_mapping(db, images, work / f"sparse_{width}")
    wall, cpu = time.time() - t0, cpu_seconds() - c0
    if not models:
        return {"size": f"{width}x{height}", "models": 0, "registered": 0}
    best = max(models.values(), key=lambda r: r.num_reg_images())
    (camera,) = best.cameras.values()
    focal = camera.params[0]
    return {
        "size": f"{width}x{height}",
        "true_focal_px": true_focal,
        "models": len(models),
        "registered": best.num_reg_images(),
        "focal_px": focal,
        "focal_error_percent": 100.0 * (focal / true_focal - 1.0),
        "k1": camera.params[3],
        "mean_reprojection_error_px": best.compute_mean_reprojection_error(),
        "wall_s": wall,
        "cpu_s": cpu,
    }


def main():
    if len(sys.argv) != 2:
        raise SystemExit(__doc__)
    fresco = sys.argv[1]
    work = Path(tempfile.mkdtemp(prefix="colmap_hard_focal_"))
    try:
        results = [run(fresco, w, h, work) for w, h in SIZES]
    finally:
        shutil.rmtree(work)
    info = {
        "case": "issue 18 (b): no EXIF, true focal 4x the default prior, torus ring of 16, seed 3",
        "pycolmap": pycolmap.__version__,
        "options": "pycolmap defaults, one SIMPLE_RADIAL camera for all images",
        "results": results,
    }
    out = HERE / "colmap" / "hard_focal_4x.json"
    out.write_text(json.dumps(info, indent=2) + "\n")
    print(json.dumps(info, indent=2))


if __name__ == "__main__":
    main()
