#!/usr/bin/env python3
"""Helpers of bench/match.sh (issue 3, matching + two-view verification).

  prepare <ws>   OpenCV SIFT (defaults) on the 16 templeSparseRing images, written as a fresco
                 workspace (images.json with the Middlebury K as a calibration-file prior,
                 features/<name>.sift in fresco's version-1 layout, keypoints shifted by +0.5
                 px to COLMAP's pixel convention like core's Middlebury reader), plus
                 <ws>/opencv_features.npz for the OpenCV run. Both tools then match exactly
                 the same keypoints and descriptors.
  opencv <ws>    OpenCV on every one of the 120 pairs: BFMatcher NORM_L2 knnMatch k=2 with
                 ratio 0.8 plus the mutual check (what `fresco match` does), then
                 findEssentialMat (RANSAC, 0.999, 4 px: fresco's default threshold) and
                 recoverPose. Prints one JSON line: wall and CPU seconds, pairs, verified pairs, inliers.
  pair <dir> <image1> <image2> [nfeatures]
                 OpenCV SIFT of two photos (nfeatures 0 = all) written as fresco feature files
                 <dir>/a.sift and <dir>/b.sift, for the throughput comparison.
  throughput <dir> [runs]
                 OpenCV BFMatcher (NORM_L2, default threads) knnMatch k=2 of a.sift against
                 b.sift (the same u8 descriptors as f32), median of runs (default 5); also the
                 reverse match() a mutual check needs. One JSON line with descriptor pairs/s.
"""
import json
import struct
import sys
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
TEMPLE = ROOT / "datasets" / "templeSparseRing"


def prepare(ws):
    ws.mkdir(parents=True, exist_ok=True)
    (ws / "features").mkdir(exist_ok=True)
    par = {}
    for line in (TEMPLE / "templeSR_par.txt").read_text().split("\n")[1:]:
        f = line.split()
        if f:
            par[f[0]] = np.array(list(map(float, f[1:10]))).reshape(3, 3)
    sift = cv2.SIFT_create()
    images, npz = [], {}
    for i, name in enumerate(sorted(par), start=1):
        grey = cv2.imread(str(TEMPLE / name), cv2.IMREAD_GRAYSCALE)
        h, w = grey.shape
        kps, desc = sift.detectAndCompute(grey, None)
        desc_u8 = np.clip(np.round(desc), 0, 255).astype(np.uint8)
        header = b"FRSIFT\0\0" + struct.pack("<6I", 1, len(kps), 128, 0, w, h)
        kp = np.array(
            [(k.pt[0] + 0.5, k.pt[1] + 0.5, k.size / 2.0, np.radians(k.angle)) for k in kps],
            dtype="<f4",
        )
        (ws / "features" / f"{name}.sift").write_bytes(header + kp.tobytes() + desc_u8.tobytes())
        npz[f"kp{i}"] = kp[:, :2].astype(np.float64)
        npz[f"desc{i}"] = desc_u8.astype(np.float32)
        k = par[name]
        images.append(
            {
                "id": i,
                "name": name,
                "path": str(TEMPLE / name),
                "width": w,
                "height": h,
                "num_keypoints": len(kps),
                "prior": {
                    "focal_x": k[0, 0],
                    "focal_y": k[1, 1],
                    "cx": k[0, 2] + 0.5,
                    "cy": k[1, 2] + 0.5,
                    "source": "calibration_file",
                },
                "exif_orientation": None,
                "camera_make": None,
                "camera_model": None,
            }
        )
        npz[f"K{i}"] = np.array(
            [[k[0, 0], 0, k[0, 2] + 0.5], [0, k[1, 1], k[1, 2] + 0.5], [0, 0, 1]]
        )
    (ws / "images.json").write_text(json.dumps({"version": 1, "images": images}, indent=1))
    np.savez(ws / "opencv_features.npz", **npz)
    print(json.dumps({"images": len(images), "keypoints": sum(im["num_keypoints"] for im in images)}))


def opencv(ws):
    data = np.load(ws / "opencv_features.npz")
    n = len([k for k in data.files if k.startswith("kp")])
    kp = [data[f"kp{i}"] for i in range(1, n + 1)]
    desc = [data[f"desc{i}"] for i in range(1, n + 1)]
    ks = [data[f"K{i}"] for i in range(1, n + 1)]
    cv2.setRNGSeed(0)
    matcher = cv2.BFMatcher(cv2.NORM_L2)
    t0 = time.perf_counter()
    c0 = time.process_time()
    pairs = verified = inliers = 0
    match_seconds = 0.0
    for a in range(n):
        for b in range(a + 1, n):
            pairs += 1
            tm = time.perf_counter()
            fwd = matcher.knnMatch(desc[a], desc[b], k=2)
            back = matcher.match(desc[b], desc[a])
            best_back = {m.queryIdx: m.trainIdx for m in back}
            good = [
                (m.queryIdx, m.trainIdx)
                for m, s in (p for p in fwd if len(p) == 2)
                if m.distance < 0.8 * s.distance and best_back.get(m.trainIdx) == m.queryIdx
            ]
            match_seconds += time.perf_counter() - tm
            if len(good) < 15:
                continue
            idx = np.array(good)
            p1, p2 = kp[a][idx[:, 0]], kp[b][idx[:, 1]]
            # One K per pair in OpenCV's API; the temple images share theirs.
            e, mask = cv2.findEssentialMat(p1, p2, ks[a], method=cv2.RANSAC, prob=0.999, threshold=4.0)
            if e is None or mask is None:
                continue
            count, _, _, _ = cv2.recoverPose(e[:3], p1, p2, ks[a], mask=mask.copy())
            k = int(mask.sum())
            if k >= 15:
                verified += 1
                inliers += k
    seconds = time.perf_counter() - t0
    cpu = time.process_time() - c0
    print(json.dumps({"seconds": seconds, "cpu_seconds": cpu, "match_seconds": match_seconds, "pairs": pairs,
                      "verified": verified, "inliers": inliers}))


def write_sift(path, kps, desc, w, h):
    desc_u8 = np.clip(np.round(desc), 0, 255).astype(np.uint8)
    header = b"FRSIFT\0\0" + struct.pack("<6I", 1, len(kps), 128, 0, w, h)
    kp = np.array(
        [(k.pt[0] + 0.5, k.pt[1] + 0.5, k.size / 2.0, np.radians(k.angle)) for k in kps],
        dtype="<f4",
    )
    Path(path).write_bytes(header + kp.tobytes() + desc_u8.tobytes())


def read_sift_descriptors(path):
    data = Path(path).read_bytes()
    n = struct.unpack("<6I", data[8:32])[1]
    off = 32 + 16 * n
    return np.frombuffer(data[off:off + 128 * n], dtype=np.uint8).reshape(n, 128)


def pair(out, image1, image2, nfeatures="0"):
    out.mkdir(parents=True, exist_ok=True)
    sift = cv2.SIFT_create(nfeatures=int(nfeatures))
    for name, image in (("a", image1), ("b", image2)):
        grey = cv2.imread(image, cv2.IMREAD_GRAYSCALE)
        kps, desc = sift.detectAndCompute(grey, None)
        write_sift(out / f"{name}.sift", kps, desc, grey.shape[1], grey.shape[0])
    print(json.dumps({"a": image1, "b": image2}))


def throughput(out, runs="5"):
    a = read_sift_descriptors(out / "a.sift").astype(np.float32)
    b = read_sift_descriptors(out / "b.sift").astype(np.float32)
    matcher = cv2.BFMatcher(cv2.NORM_L2)
    knn, both = [], []
    for _ in range(int(runs)):
        t0 = time.perf_counter()
        fwd = matcher.knnMatch(a, b, k=2)
        t1 = time.perf_counter()
        back = matcher.match(b, a)
        t2 = time.perf_counter()
        knn.append(t1 - t0)
        both.append(t2 - t0)
    best_back = {m.queryIdx: m.trainIdx for m in back}
    good = sum(1 for p in fwd if len(p) == 2 and p[0].distance < 0.8 * p[1].distance
               and best_back.get(p[0].trainIdx) == p[0].queryIdx)
    knn_s, both_s = float(np.median(knn)), float(np.median(both))
    print(json.dumps({"n1": len(a), "n2": len(b), "matches": good, "runs": int(runs),
                      "knn_seconds": knn_s, "knn_pairs_per_second": len(a) * len(b) / knn_s,
                      "mutual_seconds": both_s, "mutual_pairs_per_second": len(a) * len(b) / both_s,
                      "threads": cv2.getNumThreads()}))


if __name__ == "__main__":
    cmd = sys.argv[1]
    if cmd in ("prepare", "opencv"):
        {"prepare": prepare, "opencv": opencv}[cmd](Path(sys.argv[2]))
    elif cmd == "pair":
        pair(Path(sys.argv[2]), *sys.argv[3:])
    elif cmd == "throughput":
        throughput(Path(sys.argv[2]), *sys.argv[3:])
