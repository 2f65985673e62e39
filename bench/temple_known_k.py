"""templeSparseRing with the Middlebury calibration given to COLMAP (pycolmap), as fresco gets it
with `--focal-file`: PINHOLE camera, focal length and principal point fixed in bundle
adjustment. Writes the best model to <out>/ for `fresco eval poses`. Used by
bench/temple_known_k.sh; needs pycolmap (PYTHON, default /work/venv)."""
import sys
from pathlib import Path

import pycolmap

from colmap_run import reconstruct

reader = pycolmap.ImageReaderOptions()
reader.camera_model = "PINHOLE"
reader.camera_params = "1520.4,1525.9,302.32,246.87"  # templeSR_par.txt, the same for all photos
opts = pycolmap.IncrementalPipelineOptions()
opts.ba_refine_focal_length = False
opts.ba_refine_principal_point = False
opts.ba_refine_extra_params = False
best, n_models, names, seconds = reconstruct(Path(sys.argv[1]), Path(sys.argv[2]), reader, opts)
print(f"COLMAP known K: {best.num_reg_images()} of {len(names)} registered, {n_models} models, "
      f"{seconds:.1f} s")
