#!/usr/bin/env python3
"""Fraction of a fused cloud's points inside an axis-aligned box (issue 13: templeSparseRing's
published tight bounding box), optionally grown by a margin (fraction of the box diagonal).

    python3 bench/dense_bbox.py <fused.ply> xmin ymin zmin xmax ymax zmax [margin]
"""
import sys

import numpy as np


def read_ply_xyz(path):
    with open(path, "rb") as f:
        props, count, fmt = [], 0, None
        while True:
            line = f.readline().decode("ascii").strip()
            if line.startswith("format"):
                fmt = line.split()[1]
            elif line.startswith("element vertex"):
                count = int(line.split()[2])
            elif line.startswith("property") and count and not line.startswith("property list"):
                props.append((line.split()[2], line.split()[1]))
            elif line == "end_header":
                break
        if fmt != "binary_little_endian":
            raise SystemExit(f"{path}: expected binary_little_endian, found {fmt}")
        types = {"float": "<f4", "double": "<f8", "uchar": "u1", "uint8": "u1", "int": "<i4",
                 "uint": "<u4", "float32": "<f4", "float64": "<f8", "short": "<i2", "ushort": "<u2"}
        dtype = np.dtype([(n, types[t]) for n, t in props])
        data = np.frombuffer(f.read(dtype.itemsize * count), dtype=dtype, count=count)
    return np.stack([data["x"], data["y"], data["z"]], axis=1).astype(np.float64)


def main():
    path = sys.argv[1]
    lo = np.array([float(v) for v in sys.argv[2:5]])
    hi = np.array([float(v) for v in sys.argv[5:8]])
    margin = float(sys.argv[8]) if len(sys.argv) > 8 else 0.0
    pad = margin * np.linalg.norm(hi - lo)
    xyz = read_ply_xyz(path)
    inside = np.all((xyz >= lo - pad) & (xyz <= hi + pad), axis=1)
    print(f"points {len(xyz)} inside {inside.sum()} fraction {inside.mean():.4f} (margin {margin})")


if __name__ == "__main__":
    main()
