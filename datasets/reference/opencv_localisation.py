"""OpenCV SIFT keypoint localisation under known warps (issue 3, two-view accuracy).

Run from the repository root:  /work/venv/bin/python datasets/reference/opencv_localisation.py

Writes datasets/reference/opencv/sift_localisation.json: for the three images of
sift_warps.json (two temple photos, a 640x480 sceaux crop) and four warps with sub-pixel
translations (a pure shift, scale 0.7, scale 1.4, a 17 degree rotation), OpenCV's keypoint
position errors per octave.

Images and warps are built exactly as in opencv_sift.py (u8 Rec. 601 grey, float64 bilinear
inverse warp, pixel centres at integers), so sfm/tests/sift_repeatability.rs rebuilds the same
pixels and measures fresco with the same definitions:

* a source keypoint (x, y, sigma = size / 2) is visible when it and its image by H lie at least
  4 px inside their images;
* its repeat is the warped keypoint nearest to H(x, y) whose sigma is within a factor 1.3 of
  sigma * s_H (s_H = sqrt |det| of H's linear part) and that maps back by H^-1 within
  r = max(1.5, 0.75 sigma) source pixels of (x, y);
* the position error is |H^-1(q) - (x, y)| in source pixels; the octave is
  floor(log2(sigma / 0.8)) clamped to 0..4 (0: the 2x up-sampled octave);
* per octave: the number of repeats, the median error and the mean error vector (a bias common
  to both images cancels under the pure shift but not under scale or rotation).
"""

import json
import os
import time

import cv2
import numpy as np

from opencv_sift import OUT, ROOT, WARP_IMAGES, grey_u8, warp_bilinear

MARGIN = 4.0
SCALE_RATIO = 1.3
OCTAVES = 5


def localisation_warps(w, h):
    """(name, H source -> warped, out_w, out_h); every warp has a sub-pixel translation."""
    out = [("shift", np.array([[1.0, 0, 0.37], [0, 1.0, -0.29], [0, 0, 1.0]]), w, h)]
    for sc, (tx, ty) in [(0.7, (0.21, 0.43)), (1.4, (-0.33, 0.18))]:
        ow, oh = int(round(w * sc)), int(round(h * sc))
        H = np.array([[sc, 0, 0.5 * sc - 0.5 + tx], [0, sc, 0.5 * sc - 0.5 + ty], [0, 0, 1.0]])
        out.append((f"scale{sc}", H, ow, oh))
    t = np.deg2rad(17.0)
    c, s = np.cos(t), np.sin(t)
    cx, cy = (w - 1) / 2.0, (h - 1) / 2.0
    rot = np.array([[c, -s, cx - c * cx + s * cy + 0.3], [s, c, cy - s * cx - c * cy + 0.6], [0, 0, 1.0]])
    out.append(("rotate17", rot, w, h))
    return out


def apply(H, pts):
    p = np.c_[pts, np.ones(len(pts))] @ H.T
    return p[:, :2] / p[:, 2:3]


def inside(p, w, h):
    return (p[:, 0] >= MARGIN) & (p[:, 0] <= w - 1 - MARGIN) & (p[:, 1] >= MARGIN) & (p[:, 1] <= h - 1 - MARGIN)


def errors(k1, s1, k2, s2, H, w1, h1, w2, h2):
    """(octave, error, dx, dy) of every visible source keypoint with a repeat."""
    Hinv = np.linalg.inv(H)
    sh = np.sqrt(abs(np.linalg.det(H[:2, :2])))
    vis = inside(k1, w1, h1) & inside(apply(H, k1), w2, h2)
    back = apply(Hinv, k2)
    out = []
    for i in np.flatnonzero(vis):
        ratio = s2 / (s1[i] * sh)
        ok = (ratio <= SCALE_RATIO) & (ratio >= 1.0 / SCALE_RATIO)
        if not ok.any():
            continue
        d = back[ok] - k1[i]
        dist = np.hypot(d[:, 0], d[:, 1])
        j = int(np.argmin(dist))
        if dist[j] > max(1.5, 0.75 * s1[i]):
            continue
        octave = int(np.clip(np.floor(np.log2(s1[i] / 0.8)), 0, OCTAVES - 1))
        out.append((octave, float(dist[j]), float(d[j, 0]), float(d[j, 1])))
    return out


def summarise(rows):
    per = []
    for o in range(OCTAVES):
        r = [x for x in rows if x[0] == o]
        if not r:
            per.append({"octave": o, "repeats": 0})
            continue
        e = np.array([x[1] for x in r])
        per.append({
            "octave": o,
            "repeats": len(r),
            "median_error_px": float(np.median(e)),
            "mean_dx_px": float(np.mean([x[2] for x in r])),
            "mean_dy_px": float(np.mean([x[3] for x in r])),
        })
    return per


def main():
    sift = cv2.SIFT_create()
    record = {"opencv_version": cv2.__version__, "margin_px": MARGIN, "scale_ratio": SCALE_RATIO,
              "images": [], "pooled": None}
    pooled = []
    for name, path, crop in WARP_IMAGES:
        g = grey_u8(path, crop)
        h, w = g.shape
        kp1 = sift.detect(g, None)
        k1 = np.array([k.pt for k in kp1], np.float64).reshape(-1, 2)
        s1 = np.array([k.size / 2.0 for k in kp1])
        entry = {"name": name, "path": os.path.relpath(path, ROOT), "crop": crop, "warps": []}
        for wname, H, ow, oh in localisation_warps(w, h):
            img = warp_bilinear(g, H, ow, oh)
            kp2 = sift.detect(img, None)
            k2 = np.array([k.pt for k in kp2], np.float64).reshape(-1, 2)
            s2 = np.array([k.size / 2.0 for k in kp2])
            rows = errors(k1, s1, k2, s2, H, w, h, ow, oh)
            pooled += rows
            per = summarise(rows)
            entry["warps"].append({"name": wname, "homography": H.tolist(), "width": ow,
                                   "height": oh, "per_octave": per})
            print(f"{name} {wname}: " + ", ".join(
                f"o{p['octave']} {p['repeats']} {p.get('median_error_px', float('nan')):.3f}" for p in per))
        record["images"].append(entry)
    record["pooled"] = summarise(pooled)
    print("pooled: " + ", ".join(
        f"o{p['octave']} n={p['repeats']} median {p.get('median_error_px', float('nan')):.3f} px "
        f"bias ({p.get('mean_dx_px', float('nan')):+.3f}, {p.get('mean_dy_px', float('nan')):+.3f})"
        for p in record["pooled"]))
    path = os.path.join(OUT, "sift_localisation.json")
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        json.dump(record, f, indent=1)
    os.replace(tmp, path)


if __name__ == "__main__":
    t0 = time.time()
    main()
    print(f"done in {time.time() - t0:.1f} s")
