#!/usr/bin/env python3
"""One timed pycolmap run (SIFT extraction, exhaustive matching, incremental mapping) on an
image folder, as bench/sfm.sh compares it with fresco. Prints one JSON line:
{"wall": s, "cpu": s, "extract": s, "match": s, "map": s, "registered": n, "images": n}
(phase times are wall seconds).
Usage: sfm_colmap.py <image dir>"""
import json
import resource
import sys
import tempfile
import time
from pathlib import Path

import pycolmap


def cpu():
    s = resource.getrusage(resource.RUSAGE_SELF)
    return s.ru_utime + s.ru_stime


image_dir = Path(sys.argv[1])
names = sorted(p.name for p in image_dir.iterdir() if p.suffix.lower() in (".png", ".jpg", ".jpeg"))
with tempfile.TemporaryDirectory() as work:
    db = Path(work) / "database.db"
    t0, c0 = time.time(), cpu()
    pycolmap.extract_features(db, image_dir, image_names=names, camera_mode=pycolmap.CameraMode.SINGLE)
    t1 = time.time()
    pycolmap.match_exhaustive(db)
    t2 = time.time()
    models = pycolmap.incremental_mapping(db, image_dir, Path(work) / "sparse")
    t3 = time.time()
    wall, c = t3 - t0, cpu() - c0
    reg = max((m.num_reg_images() for m in models.values()), default=0)
print(json.dumps({"wall": wall, "cpu": c, "extract": t1 - t0, "match": t2 - t1, "map": t3 - t2,
                  "registered": reg, "images": len(names)}))
