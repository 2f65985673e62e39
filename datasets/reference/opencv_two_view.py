#!/usr/bin/env python3
"""OpenCV two-view references for fresco's matching and verification (issue 3).

For five templeSparseRing pairs of ring neighbours (23 degrees apart: (1,2), (3,4), (6,7),
(8,9), (12,13); the ring order of the file names is not the capture order, e.g. 5 and 6 are
123 degrees apart and barely overlap), this script writes
datasets/reference/opencv/two_view_pairs.json with, per pair:

- the putative correspondences: cv2.SIFT_create() (defaults) on the grey image, BFMatcher
  (NORM_L2) knnMatch k=2, Lowe ratio 0.8 (no mutual check), as x1 y1 x2 y2 in pixels, OpenCV's
  convention (the centre of the top-left pixel is (0, 0), as in the Middlebury K);
- cv2.findEssentialMat(RANSAC, prob 0.999, threshold 1 px) with the ground-truth K: E, the
  inlier indices, and cv2.recoverPose's R, t on those inliers;
- cv2.findFundamentalMat(FM_RANSAC, 1 px, 0.999): F and its inlier indices;
- the ground-truth relative pose cam2_from_cam1 from templeSR_par.txt (x_cam = R x_world + t:
  R_rel = R2 R1^T, t_rel = t2 - R_rel t1, normalised) and the rotation error of OpenCV's R.

With --ring, the same for all 16 pairs of file-name neighbours 0001/0002 ... 0016/0001 (a
wider check; some of them barely overlap, see above), written to two_view_ring.json; pairs
where OpenCV finds no essential matrix are kept with "essential": null.

Usage: /work/venv/bin/python datasets/reference/opencv_two_view.py [--ring]
"""
import json
import platform
import sys
import time
from pathlib import Path

import cv2
import numpy as np

HERE = Path(__file__).resolve().parent
TEMPLE = HERE.parent / "templeSparseRing"
OUT = HERE / "opencv" / "two_view_pairs.json"
PAIRS = [(1, 2), (3, 4), (6, 7), (8, 9), (12, 13)]


def read_par(path):
    views = {}
    lines = path.read_text().split("\n")
    for line in lines[1:]:
        f = line.split()
        if not f:
            continue
        v = list(map(float, f[1:]))
        views[f[0]] = (
            np.array(v[0:9]).reshape(3, 3),
            np.array(v[9:18]).reshape(3, 3),
            np.array(v[18:21]),
        )
    return views


def rotation_angle_deg(r):
    return float(np.degrees(np.arccos(np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0))))


def name(i):
    return f"templeSR{i:04d}.png"


def main():
    ring = "--ring" in sys.argv[1:]
    pairs = [(i, i % 16 + 1) for i in range(1, 17)] if ring else PAIRS
    out = OUT.with_name("two_view_ring.json") if ring else OUT
    cv2.setRNGSeed(0)
    views = read_par(TEMPLE / "templeSR_par.txt")
    sift = cv2.SIFT_create()
    matcher = cv2.BFMatcher(cv2.NORM_L2)
    features = {}

    def detect(i):
        if i not in features:
            grey = cv2.imread(str(TEMPLE / name(i)), cv2.IMREAD_GRAYSCALE)
            features[i] = sift.detectAndCompute(grey, None)
        return features[i]

    out_pairs = []
    for a, b in pairs:
        (kp1, d1), (kp2, d2) = detect(a), detect(b)
        knn = matcher.knnMatch(d1, d2, k=2)
        good = [m for m, n in (p for p in knn if len(p) == 2) if m.distance < 0.8 * n.distance]
        # Rounded to 1/1000 px for the committed text; the estimates below use the rounded values
        # too, so fresco and OpenCV see exactly the same numbers.
        pts1 = np.round(np.array([kp1[m.queryIdx].pt for m in good], dtype=np.float64), 3)
        pts2 = np.round(np.array([kp2[m.trainIdx].pt for m in good], dtype=np.float64), 3)
        k1, r1, t1 = views[name(a)]
        k2, r2, t2 = views[name(b)]
        assert np.allclose(k1, k2), "the pair's intrinsics differ"
        k = k1
        r_gt = r2 @ r1.T
        t_gt = t2 - r_gt @ t1
        t_gt = t_gt / np.linalg.norm(t_gt)
        if len(good) < 5:
            print(f"{name(a)} {name(b)}: {len(good)} matches, no essential matrix")
            out_pairs.append(
                {
                    "image1": name(a),
                    "image2": name(b),
                    "K": k.tolist(),
                    "num_keypoints": [len(kp1), len(kp2)],
                    "correspondences": [[*p, *q] for p, q in zip(pts1.tolist(), pts2.tolist())],
                    "essential": None,
                    "gt_cam2_from_cam1_R": r_gt.tolist(),
                    "gt_cam2_from_cam1_t": t_gt.tolist(),
                    "gt_rotation_angle_deg": rotation_angle_deg(r_gt),
                }
            )
            continue
        t0 = time.perf_counter()
        e, emask = cv2.findEssentialMat(pts1, pts2, k, method=cv2.RANSAC, prob=0.999, threshold=1.0)
        e_seconds = time.perf_counter() - t0
        e = e[:3]  # several solutions may be stacked; OpenCV returns the best first
        _, r, t, pose_mask = cv2.recoverPose(e, pts1, pts2, k, mask=emask.copy())
        f, fmask = cv2.findFundamentalMat(pts1, pts2, cv2.FM_RANSAC, 1.0, 0.999)
        if f is None or fmask is None:
            f, fmask = np.zeros((3, 3)), np.zeros(len(good), dtype=np.uint8)
        f = f[:3]
        rot_err = rotation_angle_deg(r.T @ r_gt)
        t_err = float(np.degrees(np.arccos(np.clip(float(t.ravel() @ t_gt), -1.0, 1.0))))
        pair = {
            "image1": name(a),
            "image2": name(b),
            "K": k.tolist(),
            "num_keypoints": [len(kp1), len(kp2)],
            "correspondences": [[*p, *q] for p, q in zip(pts1.tolist(), pts2.tolist())],
            "essential": (e / np.linalg.norm(e)).tolist(),
            "essential_inliers": np.flatnonzero(emask.ravel()).tolist(),
            "essential_seconds": e_seconds,
            "cam2_from_cam1_R": r.tolist(),
            "cam2_from_cam1_t": t.ravel().tolist(),
            "pose_in_front": int(np.count_nonzero(pose_mask)),
            "fundamental": (f / np.linalg.norm(f)).tolist(),
            "fundamental_inliers": np.flatnonzero(fmask.ravel()).tolist(),
            "gt_cam2_from_cam1_R": r_gt.tolist(),
            "gt_cam2_from_cam1_t": t_gt.tolist(),
            "gt_rotation_angle_deg": rotation_angle_deg(r_gt),
            "opencv_rotation_error_deg": rot_err,
            "opencv_translation_error_deg": t_err,
        }
        print(
            f"{name(a)} {name(b)}: {len(good)} matches, E inliers {int(emask.sum())}, "
            f"F inliers {int(fmask.sum())}, GT angle {pair['gt_rotation_angle_deg']:.2f} deg, "
            f"OpenCV rotation error {rot_err:.3f} deg, translation error {t_err:.2f} deg"
        )
        out_pairs.append(pair)
    out.parent.mkdir(parents=True, exist_ok=True)
    doc = {
        "opencv": cv2.__version__,
        "python": platform.python_version(),
        "matching": "SIFT_create() defaults, BFMatcher NORM_L2 knnMatch k=2, ratio 0.8",
        "essential": "findEssentialMat RANSAC prob 0.999 threshold 1.0 px, recoverPose",
        "fundamental": "findFundamentalMat FM_RANSAC 1.0 px 0.999",
        "pixel_convention": "OpenCV/Middlebury: centre of the top-left pixel at (0, 0)",
        "pairs": out_pairs,
    }
    tmp = out.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(doc, separators=(",", ":")) + "\n")
    tmp.replace(out)
    print(f"wrote {out} ({out.stat().st_size} bytes)")


if __name__ == "__main__":
    main()
