"""templeSparseRing without calibration, with the principal point refined in bundle adjustment
by COLMAP (pycolmap, `ba_refine_principal_point = True`, defaults otherwise: SIMPLE_RADIAL,
one camera), as `fresco reconstruct --single-camera --refine-principal-point` runs it. Writes
the best model to <out>/ for `fresco eval poses`. Used by bench/temple_refine_pp.sh; needs
pycolmap (PYTHON, default /work/venv)."""
import sys
import time
from pathlib import Path

import pycolmap

images = Path(sys.argv[1])
out = Path(sys.argv[2])
work = out.parent / (out.name + "_work")
work.mkdir(parents=True, exist_ok=True)
db = work / "database.db"
if db.exists():
    db.unlink()
names = sorted(p.name for p in images.iterdir() if p.suffix.lower() == ".png")
t0 = time.time()
pycolmap.extract_features(db, images, image_names=names, camera_mode=pycolmap.CameraMode.SINGLE)
pycolmap.match_exhaustive(db)
opts = pycolmap.IncrementalPipelineOptions()
opts.ba_refine_principal_point = True
models = pycolmap.incremental_mapping(db, images, work / "sparse", options=opts)
best = max(models.values(), key=lambda r: r.num_reg_images())
out.mkdir(parents=True, exist_ok=True)
best.write_text(str(out))
cam = next(iter(best.cameras.values()))
print(f"COLMAP, principal point refined: {best.num_reg_images()} of {len(names)} registered, "
      f"{len(models)} models, camera {cam.params}, {time.time() - t0:.1f} s")
