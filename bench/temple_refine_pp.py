"""templeSparseRing without calibration, with the principal point refined in bundle adjustment
by COLMAP (pycolmap, `ba_refine_principal_point = True`, defaults otherwise: SIMPLE_RADIAL,
one camera), as `fresco reconstruct --single-camera --refine-principal-point` runs it. Writes
the best model to <out>/ for `fresco eval poses`. Used by bench/temple_refine_pp.sh; needs
pycolmap (PYTHON, default /work/venv)."""
import sys
from pathlib import Path

import pycolmap

from colmap_run import reconstruct

opts = pycolmap.IncrementalPipelineOptions()
opts.ba_refine_principal_point = True
best, n_models, names, seconds = reconstruct(Path(sys.argv[1]), Path(sys.argv[2]), None, opts)
cam = next(iter(best.cameras.values()))
print(f"COLMAP, principal point refined: {best.num_reg_images()} of {len(names)} registered, "
      f"{n_models} models, camera {cam.params}, {seconds:.1f} s")
