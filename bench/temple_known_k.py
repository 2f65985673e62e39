"""templeSparseRing with the Middlebury calibration given to COLMAP (pycolmap), as fresco gets it
with `--focal-file`: PINHOLE camera, focal length and principal point fixed in bundle
adjustment. Writes the best model to <out>/ for `fresco eval poses`. Used by
bench/temple_known_k.sh; needs pycolmap (PYTHON, default /work/venv)."""
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
reader = pycolmap.ImageReaderOptions()
reader.camera_model = "PINHOLE"
reader.camera_params = "1520.4,1525.9,302.32,246.87"  # templeSR_par.txt, the same for all photos
t0 = time.time()
pycolmap.extract_features(db, images, image_names=names, camera_mode=pycolmap.CameraMode.SINGLE,
                          reader_options=reader)
pycolmap.match_exhaustive(db)
opts = pycolmap.IncrementalPipelineOptions()
opts.ba_refine_focal_length = False
opts.ba_refine_principal_point = False
opts.ba_refine_extra_params = False
models = pycolmap.incremental_mapping(db, images, work / "sparse", options=opts)
best = max(models.values(), key=lambda r: r.num_reg_images())
out.mkdir(parents=True, exist_ok=True)
best.write_text(str(out))
print(f"COLMAP known K: {best.num_reg_images()} of {len(names)} registered, {len(models)} models, "
      f"{time.time() - t0:.1f} s")
