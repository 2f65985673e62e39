"""OpenCV SIFT reference outputs for fresco's feature tests (issue 3).

Run from the repository root:  /work/venv/bin/python datasets/reference/opencv_sift.py

Writes, under datasets/reference/opencv/:

* sift_keypoints_<image>.txt for three templeSparseRing photos: one line per cv2.SIFT keypoint,
  "x y size angle response", OpenCV conventions (pixel centres at integer coordinates,
  size = 2 * sigma, angle in degrees measured so that fresco's orientation = 360 - angle).
* sift_warps.json: for 2 temple photos and a 640x480 crop of a sceaux photo, a fixed set of warps
  (rotation 30 and 90 degrees, scale 0.5/0.75/1.5/2, a perspective warp, brightness x0.7 + 20)
  with their homographies and OpenCV's repeatability and matching precision at 1.5 px.

Images and warps are defined so that the Rust test (sfm/tests/sift_repeatability.rs) rebuilds
exactly the same pixels:
* grey = round(0.299 R + 0.587 G + 0.114 B) as u8 (Rec. 601, from the 8-bit RGB file);
* warped(x, y) = bilinear sample of grey at H^-1 (x, y, 1) (pixel centres at integers), computed
  here in float64 with numpy (NOT cv2.warpPerspective, whose 1/32-pixel fixed-point coordinates
  would differ slightly from the Rust warp); samples whose 2x2 neighbourhood leaves the image are
  0; the result is rounded to u8;
* brightness: clip(round(0.7 v + 20), 0, 255) on the u8 grey.

Repeatability and precision (same definitions in the Rust test):
* a keypoint of the source image is visible when it lies at least 4 px inside the source and its
  image by H at least 4 px inside the warped image; likewise for warped keypoints with H^-1;
  keypoints at the same position (several orientations) count once for repeatability;
* repeatability = (visible source positions with a visible warped position within 1.5 px after
  mapping by H) / min(visible source positions, visible warped positions);
* precision = among Lowe ratio-test matches (nearest / second nearest L2 descriptor distance
  < 0.8) from the visible source keypoints to the visible warped keypoints, the fraction whose
  source keypoint maps by H within 1.5 px of the matched keypoint.
"""

import json
import os
import sys
import time

import cv2
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
OUT = os.path.join(ROOT, "datasets", "reference", "opencv")
TEMPLE = os.path.join(ROOT, "datasets", "templeSparseRing")
SCEAUX = os.path.join(ROOT, "datasets", "sceaux_castle", "images")

KEYPOINT_IMAGES = ["templeSR0001.png", "templeSR0005.png", "templeSR0009.png"]
# (name, path, crop (x0, y0, w, h) or None)
WARP_IMAGES = [
    ("templeSR0001", os.path.join(TEMPLE, "templeSR0001.png"), None),
    ("templeSR0009", os.path.join(TEMPLE, "templeSR0009.png"), None),
    ("sceaux_100_7100_crop", os.path.join(SCEAUX, "100_7100.JPG"), (480, 361, 640, 480)),
]
MARGIN = 4.0
TOLERANCE = 1.5
RATIO = 0.8


def grey_u8(path, crop=None):
    bgr = cv2.imread(path, cv2.IMREAD_COLOR)
    if bgr is None:
        sys.exit(f"cannot read {path}")
    rgb = bgr[:, :, ::-1].astype(np.float64)
    g = np.round(0.299 * rgb[:, :, 0] + 0.587 * rgb[:, :, 1] + 0.114 * rgb[:, :, 2])
    g = np.clip(g, 0, 255).astype(np.uint8)
    if crop is not None:
        x0, y0, w, h = crop
        g = g[y0:y0 + h, x0:x0 + w].copy()
    return g


def warp_bilinear(img, H, out_w, out_h):
    """Inverse-mapping bilinear warp, pixel centres at integers, 0 outside."""
    Hinv = np.linalg.inv(H)
    ys, xs = np.mgrid[0:out_h, 0:out_w].astype(np.float64)
    den = Hinv[2, 0] * xs + Hinv[2, 1] * ys + Hinv[2, 2]
    sx = (Hinv[0, 0] * xs + Hinv[0, 1] * ys + Hinv[0, 2]) / den
    sy = (Hinv[1, 0] * xs + Hinv[1, 1] * ys + Hinv[1, 2]) / den
    h, w = img.shape
    x0 = np.floor(sx)
    y0 = np.floor(sy)
    inside = (x0 >= 0) & (y0 >= 0) & (x0 + 1 <= w - 1) & (y0 + 1 <= h - 1)
    fx = sx - x0
    fy = sy - y0
    x0i = np.clip(x0, 0, w - 2).astype(np.int64)
    y0i = np.clip(y0, 0, h - 2).astype(np.int64)
    f = img.astype(np.float64)
    v = ((1 - fx) * (1 - fy) * f[y0i, x0i] + fx * (1 - fy) * f[y0i, x0i + 1]
         + (1 - fx) * fy * f[y0i + 1, x0i] + fx * fy * f[y0i + 1, x0i + 1])
    v = np.where(inside, v, 0.0)
    return np.clip(np.floor(v + 0.5), 0, 255).astype(np.uint8)


def warps(w, h):
    """The fixed warps: (name, H (3x3, source -> warped), out_w, out_h, brightness)."""
    out = []
    cx, cy = (w - 1) / 2.0, (h - 1) / 2.0
    t = np.deg2rad(30.0)
    c, s = np.cos(t), np.sin(t)
    rot = np.array([[c, -s, cx - c * cx + s * cy], [s, c, cy - s * cx - c * cy], [0, 0, 1.0]])
    out.append(("rotate30", rot, w, h, False))
    out.append(("rotate90", np.array([[0, -1.0, h - 1], [1.0, 0, 0], [0, 0, 1.0]]), h, w, False))
    for sc in [0.5, 0.75, 1.5, 2.0]:
        ow, oh = int(round(w * sc)), int(round(h * sc))
        H = np.array([[sc, 0, 0.5 * sc - 0.5], [0, sc, 0.5 * sc - 0.5], [0, 0, 1.0]])
        out.append((f"scale{sc}", H, ow, oh, False))
    src = np.float32([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]])
    dst = np.float32([[0.08 * w, 0.06 * h], [0.9 * w, 0.0], [w - 1, h - 1], [0.0, 0.88 * h]])
    P = cv2.getPerspectiveTransform(src, dst).astype(np.float64)
    out.append(("perspective", P / P[2, 2], w, h, False))
    out.append(("brightness", np.eye(3), w, h, True))
    return out


def apply(H, pts):
    p = np.c_[pts, np.ones(len(pts))] @ H.T
    return p[:, :2] / p[:, 2:3]


def visible(pts, H, w_src, h_src, w_dst, h_dst):
    if len(pts) == 0:
        return np.zeros(0, bool)
    q = apply(H, pts)
    inside = lambda p, w, h: ((p[:, 0] >= MARGIN) & (p[:, 0] <= w - 1 - MARGIN)
                              & (p[:, 1] >= MARGIN) & (p[:, 1] <= h - 1 - MARGIN))
    return inside(pts, w_src, h_src) & inside(q, w_dst, h_dst)


def unique_positions(pts):
    return np.unique(np.round(pts, 3), axis=0) if len(pts) else pts


def scores(k1, d1, k2, d2, H, w1, h1, w2, h2):
    v1 = visible(k1, H, w1, h1, w2, h2)
    v2 = visible(k2, np.linalg.inv(H), w2, h2, w1, h1)
    p1, p2 = k1[v1], k2[v2]
    u1, u2 = unique_positions(p1), unique_positions(p2)
    if len(u1) == 0 or len(u2) == 0:
        return 0.0, 0.0, 0
    m1 = apply(H, u1)
    dist = np.sqrt(((m1[:, None, :] - u2[None, :, :]) ** 2).sum(-1))
    repeated = int((dist.min(1) <= TOLERANCE).sum())
    repeatability = repeated / min(len(u1), len(u2))
    e1, e2 = d1[v1].astype(np.float64), d2[v2].astype(np.float64)
    dd = (e1 ** 2).sum(1)[:, None] + (e2 ** 2).sum(1)[None, :] - 2 * e1 @ e2.T
    dd = np.sqrt(np.maximum(dd, 0))
    correct = total = 0
    if e2.shape[0] >= 2:
        order = np.argsort(dd, axis=1)
        best, second = order[:, 0], order[:, 1]
        rows = np.arange(len(e1))
        ok = dd[rows, best] < RATIO * dd[rows, second]
        mp = apply(H, p1)
        err = np.sqrt(((mp - p2[best]) ** 2).sum(1))
        total = int(ok.sum())
        correct = int((ok & (err <= TOLERANCE)).sum())
    precision = correct / total if total else 0.0
    return repeatability, precision, total


def main():
    os.makedirs(OUT, exist_ok=True)
    sift = cv2.SIFT_create()  # OpenCV defaults: 3 layers, contrast 0.04, edge 10, sigma 1.6
    for name in KEYPOINT_IMAGES:
        g = grey_u8(os.path.join(TEMPLE, name))
        kps = sift.detect(g, None)
        path = os.path.join(OUT, f"sift_keypoints_{os.path.splitext(name)[0]}.txt")
        with open(path, "w") as f:
            f.write(f"# cv2.SIFT_create() defaults, OpenCV {cv2.__version__}, {name} "
                    f"{g.shape[1]}x{g.shape[0]}; x y size angle response; centres at integers\n")
            for k in kps:
                f.write(f"{k.pt[0]:.3f} {k.pt[1]:.3f} {k.size:.4f} {k.angle:.3f} {k.response:.6f}\n")
        print(f"{name}: {len(kps)} keypoints -> {path}")

    record = {
        "opencv_version": cv2.__version__,
        "tolerance_px": TOLERANCE,
        "ratio": RATIO,
        "margin_px": MARGIN,
        "images": [],
    }
    for name, path, crop in WARP_IMAGES:
        g = grey_u8(path, crop)
        h, w = g.shape
        k1, d1 = sift.detectAndCompute(g, None)
        p1 = np.array([k.pt for k in k1], np.float64).reshape(-1, 2)
        entry = {"name": name, "path": os.path.relpath(path, ROOT), "crop": crop,
                 "width": w, "height": h, "keypoints": len(k1), "warps": []}
        for wname, H, ow, oh, bright in warps(w, h):
            img = warp_bilinear(g, H, ow, oh)
            if bright:
                img = np.clip(np.floor(0.7 * img.astype(np.float64) + 20 + 0.5), 0, 255).astype(np.uint8)
            k2, d2 = sift.detectAndCompute(img, None)
            p2 = np.array([k.pt for k in k2], np.float64).reshape(-1, 2)
            rep, prec, n = scores(p1, d1, p2, d2, H, w, h, ow, oh)
            entry["warps"].append({
                "name": wname, "homography": H.tolist(), "width": ow, "height": oh,
                "brightness": bright, "keypoints": len(k2),
                "repeatability": rep, "precision": prec, "ratio_matches": n,
            })
            print(f"{name} {wname}: {len(k2)} kp, repeatability {rep:.3f}, "
                  f"precision {prec:.3f} ({n} matches)")
        record["images"].append(entry)
    with open(os.path.join(OUT, "sift_warps.json"), "w") as f:
        json.dump(record, f, indent=1)


if __name__ == "__main__":
    t0 = time.time()
    main()
    print(f"done in {time.time() - t0:.1f} s")
