"""Reads a model fresco wrote (`<ws>/sparse/<k>`, COLMAP text format) with COLMAP itself
(pycolmap) and checks it is the model fresco reported: the same numbers of cameras, registered
images, 3D points and observations as the text holds them; every observation reprojected with
COLMAP's own camera models and poses, and their mean within 0.01 px of fresco's reported mean
reprojection error (a mean over observations; COLMAP's compute_mean_reprojection_error is the
mean of the points' errors, printed as colmap_mean_point_error); each point's stored error
within 1e-6 px of COLMAP's recomputation. Issue 4 asks for this check outside CI (pycolmap is not a CI dependency); bench/sfm.sh
runs it on every fresco model it makes. Prints one JSON line; exits non-zero on a mismatch.

Usage: python read_fresco_model.py <model dir> [<fresco sfm summary json>]"""
import json
import math
import sys
from pathlib import Path

import numpy as np
import pycolmap


def text_counts(model: Path):
    """(cameras, images, points, observations) as the text files hold them."""
    cams = [l for l in (model / "cameras.txt").read_text().splitlines() if l and l[0] != "#"]
    lines = [l for l in (model / "images.txt").read_text().splitlines() if not l.startswith("#")]
    images = lines[0::2]
    points = [l for l in (model / "points3D.txt").read_text().splitlines() if l and l[0] != "#"]
    obs = sum((len(p.split()) - 8) // 2 for p in points)
    return len(cams), len([l for l in images if l.strip()]), len(points), obs


def main():
    model = Path(sys.argv[1])
    rec = pycolmap.Reconstruction(str(model))
    n_cams, n_images, n_points, n_obs = text_counts(model)
    errors = []
    worst_stored = 0.0
    for p in rec.points3D.values():
        e = []
        for el in p.track.elements:
            image = rec.images[el.image_id]
            camera = rec.cameras[image.camera_id]
            pixel = camera.img_from_cam(image.cam_from_world() * p.xyz)
            e.append(float(np.linalg.norm(pixel - image.points2D[el.point2D_idx].xy)))
        errors += e
        worst_stored = max(worst_stored, abs(p.error - float(np.mean(e))))
    got = {
        "cameras": rec.num_cameras(),
        "registered": rec.num_reg_images(),
        "points": rec.num_points3D(),
        "observations": len(errors),
        "mean_reprojection_px": float(np.mean(errors)),
        "colmap_mean_point_error": rec.compute_mean_reprojection_error(),
        "worst_stored_point_error_px": worst_stored,
    }
    problems = []
    if worst_stored > 1e-6:
        problems.append(f"a point's stored error is {worst_stored:.2e} px from COLMAP's")
    for key, want in [("cameras", n_cams), ("registered", n_images), ("points", n_points),
                      ("observations", n_obs)]:
        if got[key] != want:
            problems.append(f"{key}: COLMAP read {got[key]}, the text holds {want}")
    if len(sys.argv) > 2:
        summary = json.loads(Path(sys.argv[2]).read_text())
        sfm = summary.get("sfm", summary)
        for key in ("registered", "points"):
            if key in sfm and sfm[key] != got[key]:
                problems.append(f"{key}: COLMAP read {got[key]}, fresco reported {sfm[key]}")
        fr = sfm.get("mean_reprojection_px")
        if fr is not None and not math.isclose(fr, got["mean_reprojection_px"], abs_tol=0.01):
            problems.append(f"mean reprojection: COLMAP {got['mean_reprojection_px']:.4f} px, "
                            f"fresco {fr:.4f} px")
    got["model"] = str(model)
    got["problems"] = problems
    print(json.dumps(got))
    sys.exit(1 if problems else 0)


if __name__ == "__main__":
    main()
