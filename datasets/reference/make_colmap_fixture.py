#!/usr/bin/env python3
"""Reference COLMAP models for fresco-core's COLMAP reader/writer tests, written by pycolmap.

Run with the reference tools' interpreter (pycolmap 4.2.1 / COLMAP 4.2.1 when written):

    /work/venv/bin/python datasets/reference/make_colmap_fixture.py          # (re)write fixtures
    /work/venv/bin/python datasets/reference/make_colmap_fixture.py --check  # pycolmap reads fresco's output

Writes into core/tests/data/:
  colmap_tiny/{text,binary}/  a hand-built model: 5 cameras (every model fresco supports,
                              non-contiguous ids), 7 images (one without keypoints, one in a
                              sub-folder), 26 points (one with an id above 2^32), keypoints with
                              and without 3D points, errors from COLMAP. Trivial rigs/frames, as
                              COLMAP 4 writes for every model.
  colmap_rig/{text,binary}/   pycolmap's synthetic dataset with one 2-camera rig (sensor_from_rig
                              not identity): images.* hold the composed cam_from_world poses.
  colmap_reference.json       values COLMAP computes, for fresco's tests to compare with:
                              projections and unprojections of every tiny camera, the mean
                              reprojection error over observations, the rig images' poses.

--check builds fresco's ignored test `write_models_for_pycolmap_check`, which reads the
fixtures and writes them back with fresco into a temporary folder, then reads those with
pycolmap and compares them with the fixtures (CI has no pycolmap; this is the manual check).
"""

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pycolmap

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "core" / "tests" / "data"

TINY_CAMERAS = [
    (1, "SIMPLE_PINHOLE", 640, 480, [525.5, 320.0, 240.0]),
    (2, "PINHOLE", 800, 600, [700.25, 702.125, 399.5, 300.5]),
    (3, "SIMPLE_RADIAL", 1024, 768, [900.1, 512.3, 384.7, -0.0123]),
    (4, "RADIAL", 640, 480, [510.0, 321.7, 239.3, -0.2, 0.07]),
    (7, "OPENCV", 1280, 720, [1000.5, 1001.25, 640.1, 359.9, -0.25, 0.08, 1e-5, -2.5e-4]),
]
# (image id, camera id, name); registered in this (id) order, which is the order COLMAP writes.
TINY_IMAGES = [
    (1, 1, "frame_001.png"),
    (2, 2, "frame_002.png"),
    (3, 3, "sub/frame_003.jpg"),
    (4, 4, "frame_004.JPG"),
    (5, 7, "frame_005.png"),
    (6, 3, "frame_006.png"),
    (9, 1, "frame_009_no_keypoints.png"),
]


def look_at(center, target):
    """cam_from_world with the camera at `center` looking at `target`, y down."""
    z = target - center
    z /= np.linalg.norm(z)
    x = np.cross(np.array([0.0, 0.0, 1.0]), z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    rot = np.stack([x, y, z])  # rows: camera axes in world coordinates
    return pycolmap.Rigid3d(pycolmap.Rotation3d(rot), -rot @ center)


def build_tiny():
    rng = np.random.default_rng(20261123)
    rec = pycolmap.Reconstruction()
    cams = {}
    for cid, model, w, h, params in TINY_CAMERAS:
        cam = pycolmap.Camera(model=model, width=w, height=h, params=params, camera_id=cid)
        rec.add_camera_with_trivial_rig(cam)
        cams[cid] = cam
    points = rng.uniform(-1.0, 1.0, size=(26, 3))
    poses = {}
    keypoints = {}
    observations = {}  # point index -> [(image id, keypoint index)]
    for k, (iid, cid, name) in enumerate(TINY_IMAGES):
        angle = 2.0 * np.pi * k / len(TINY_IMAGES)
        center = np.array([6.0 * np.cos(angle), 6.0 * np.sin(angle), 1.5 + 0.1 * k])
        pose = look_at(center, rng.normal(0.0, 0.1, 3))
        poses[iid] = pose
        cam = cams[cid]
        kps = []
        if iid != 9:
            for p, xyz in enumerate(points):
                if p % 7 == k % 7:  # each image misses some points
                    continue
                uv = cam.img_from_cam(pose * xyz)
                if uv is None or not (0 <= uv[0] < cam.width and 0 <= uv[1] < cam.height):
                    continue
                observations.setdefault(p, []).append((iid, len(kps)))
                kps.append(uv + rng.normal(0.0, 0.5, 2))
            for _ in range(3):  # keypoints without a 3D point
                kps.append(rng.uniform([0, 0], [cam.width, cam.height]))
        keypoints[iid] = np.array(kps, dtype=np.float64).reshape(-1, 2)
    for iid, cid, name in TINY_IMAGES:
        image = pycolmap.Image(name=name, keypoints=keypoints[iid], camera_id=cid, image_id=iid)
        rec.add_image_with_trivial_frame(image, poses[iid])
    for p, xyz in enumerate(points):
        obs = observations.get(p, [])
        if len(obs) < 2:
            continue
        track = pycolmap.Track([pycolmap.TrackElement(i, j) for i, j in obs])
        color = rng.integers(0, 256, 3).astype(np.uint8)
        if p == 5:  # an id above 2^32 (COLMAP's point3D_t is 64-bit)
            point = pycolmap.Point3D()
            point.xyz = xyz
            point.color = color
            point.track = track
            rec.add_point3D_with_id(2**33 + 5, point)
        else:
            rec.add_point3D(xyz, track, color)
    rec.update_point_3d_errors()
    return rec


def build_rig():
    options = pycolmap.SyntheticDatasetOptions(
        num_rigs=1, num_cameras_per_rig=2, num_frames_per_rig=3, num_points3D=12,
        num_points2D_without_point3D=2,
    )
    pycolmap.set_random_seed(7)
    return pycolmap.synthesize_dataset(options)


def write(rec, out):
    for sub, fn in (("text", rec.write_text), ("binary", rec.write_binary)):
        d = out / sub
        if d.exists():
            shutil.rmtree(d)
        d.mkdir(parents=True)
        fn(str(d))


def pose_list(rigid):
    q = rigid.rotation.quat  # x, y, z, w
    t = rigid.translation
    return [float(q[3]), float(q[0]), float(q[1]), float(q[2]), float(t[0]), float(t[1]), float(t[2])]


def mean_observation_error(rec):
    errors = []
    for pid, point in rec.points3D.items():
        for el in point.track.elements:
            image = rec.image(el.image_id)
            uv = image.project_point(point.xyz)
            errors.append(np.linalg.norm(uv - image.points2D[el.point2D_idx].xy))
    return float(np.mean(errors)), len(errors)


def reference(tiny, rig):
    rng = np.random.default_rng(5)
    cams = []
    for cid, cam in sorted(tiny.cameras.items()):
        proj = []
        while len(proj) < 40:
            z = rng.uniform(0.5, 20.0)
            p = np.array([rng.uniform(-0.8, 0.8) * z, rng.uniform(-0.6, 0.6) * z, z])
            uv = cam.img_from_cam(p)
            proj.append([*map(float, p), *map(float, uv)])
        unproj = []
        for v in np.linspace(0.0, cam.height, 7):
            for u in np.linspace(0.0, cam.width, 9):
                xy = cam.cam_from_img(np.array([u, v]))
                unproj.append([float(u), float(v), float(xy[0]), float(xy[1])])
        behind = cam.img_from_cam(np.array([0.1, 0.2, -1.0]))
        cams.append({
            "camera_id": cid, "model": cam.model.name, "params": list(map(float, cam.params)),
            "projections": proj, "unprojections": unproj, "behind_projects": behind is not None,
        })
    tiny_err, tiny_obs = mean_observation_error(tiny)
    rig_err, rig_obs = mean_observation_error(rig)
    return {
        "pycolmap_version": pycolmap.__version__,
        "cameras": cams,
        "tiny": {
            "mean_observation_reprojection_error": tiny_err,
            "num_observations": tiny_obs,
            "num_reg_images": tiny.num_reg_images(),
            "num_points3D": tiny.num_points3D(),
            "mean_point_error": tiny.compute_mean_reprojection_error(),
        },
        "rig": {
            "num_observations": rig_obs,
            "mean_observation_reprojection_error": rig_err,
            "cam_from_world": {str(i): pose_list(img.cam_from_world()) for i, img in sorted(rig.images.items())},
            "names": {str(i): img.name for i, img in sorted(rig.images.items())},
        },
    }


def same_model(a, b, what):
    """Compares two pycolmap reconstructions; returns a list of differences."""
    diffs = []
    if sorted(a.cameras) != sorted(b.cameras):
        diffs.append(f"{what}: camera ids {sorted(a.cameras)} vs {sorted(b.cameras)}")
    for cid in a.cameras:
        if cid in b.cameras:
            ca, cb = a.camera(cid), b.camera(cid)
            if ca.model != cb.model or ca.width != cb.width or list(ca.params) != list(cb.params):
                diffs.append(f"{what}: camera {cid} differs")
    if sorted(a.reg_image_ids()) != sorted(b.reg_image_ids()):
        diffs.append(f"{what}: registered images differ")
    for iid in a.reg_image_ids():
        if iid not in b.images:
            continue
        ia, ib = a.image(iid), b.image(iid)
        if ia.name != ib.name or ia.camera_id != ib.camera_id:
            diffs.append(f"{what}: image {iid} name/camera differ")
        pa, pb = pose_list(ia.cam_from_world()), pose_list(ib.cam_from_world())
        if max(abs(x - y) for x, y in zip(pa, pb)) > 1e-12:
            diffs.append(f"{what}: image {iid} pose {pa} vs {pb}")
        ka = [(tuple(p.xy), p.point3D_id) for p in ia.points2D]
        kb = [(tuple(p.xy), p.point3D_id) for p in ib.points2D]
        if ka != kb:
            diffs.append(f"{what}: image {iid} keypoints differ")
    if sorted(a.point3D_ids()) != sorted(b.point3D_ids()):
        diffs.append(f"{what}: point ids differ")
    for pid in a.point3D_ids():
        if pid not in b.points3D:
            continue
        pa, pb = a.point3D(pid), b.point3D(pid)
        ta = sorted((e.image_id, e.point2D_idx) for e in pa.track.elements)
        tb = sorted((e.image_id, e.point2D_idx) for e in pb.track.elements)
        if list(pa.xyz) != list(pb.xyz) or list(pa.color) != list(pb.color) or pa.error != pb.error or ta != tb:
            diffs.append(f"{what}: point {pid} differs")
    return diffs


def check_fresco_output():
    out = Path(tempfile.mkdtemp(prefix="fresco_colmap_check_"))
    env = dict(os.environ, FRESCO_COLMAP_CHECK_OUT=str(out))
    cmd = ["cargo", "test", "-p", "fresco-core", "--test", "colmap_models", "--",
           "--ignored", "write_models_for_pycolmap_check"]
    print("running:", " ".join(cmd), f"(FRESCO_COLMAP_CHECK_OUT={out})")
    subprocess.run(cmd, cwd=ROOT, env=env, check=True)
    failures = []
    for name in ("tiny", "rig"):
        fixture = pycolmap.Reconstruction(str(DATA / f"colmap_{name}" / "binary"))
        for sub in ("text", "binary"):
            d = out / name / sub
            written = sorted(p.name for p in d.iterdir())
            rec = pycolmap.Reconstruction()
            (rec.read_text if sub == "text" else rec.read_binary)(str(d))
            diffs = same_model(fixture, rec, f"{name}/{sub}")
            # The same files without rigs/frames, as COLMAP 3.x writes them.
            legacy = Path(tempfile.mkdtemp(prefix="fresco_colmap_legacy_"))
            for p in d.iterdir():
                if not p.name.startswith(("rigs.", "frames.")):
                    shutil.copy(p, legacy / p.name)
            rec_legacy = pycolmap.Reconstruction()
            (rec_legacy.read_text if sub == "text" else rec_legacy.read_binary)(str(legacy))
            diffs += same_model(fixture, rec_legacy, f"{name}/{sub} without rigs/frames")
            print(f"{name}/{sub}: files {written}: pycolmap read it; "
                  f"{'identical model' if not diffs else 'DIFFERENCES'}")
            failures += diffs
    for f in failures:
        print("  ", f)
    shutil.rmtree(out)
    return not failures


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--check", action="store_true", help="check that pycolmap reads fresco's output")
    args = parser.parse_args()
    if args.check:
        sys.exit(0 if check_fresco_output() else 1)
    tiny = build_tiny()
    rig = build_rig()
    write(tiny, DATA / "colmap_tiny")
    write(rig, DATA / "colmap_rig")
    ref = reference(tiny, rig)
    (DATA / "colmap_reference.json").write_text(json.dumps(ref, indent=1) + "\n")
    print(f"pycolmap {pycolmap.__version__}: wrote {DATA}/colmap_tiny, colmap_rig, colmap_reference.json")
    print(tiny.summary())
    print(rig.summary())


if __name__ == "__main__":
    main()
