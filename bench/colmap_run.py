"""Shared by the bench scripts that run COLMAP (pycolmap) on a folder of PNG photos: feature
extraction, exhaustive matching and incremental mapping into a fresh database beside <out>,
and the model with the most registered images written as text to <out>/."""
import time
from pathlib import Path

import pycolmap


def reconstruct(images: Path, out: Path, reader=None, mapper=None):
    """Returns (best model, number of models, photo names, seconds)."""
    work = out.parent / (out.name + "_work")
    work.mkdir(parents=True, exist_ok=True)
    db = work / "database.db"
    if db.exists():
        db.unlink()
    names = sorted(p.name for p in images.iterdir() if p.suffix.lower() == ".png")
    t0 = time.time()
    kwargs = {} if reader is None else {"reader_options": reader}
    pycolmap.extract_features(db, images, image_names=names,
                              camera_mode=pycolmap.CameraMode.SINGLE, **kwargs)
    pycolmap.match_exhaustive(db)
    models = pycolmap.incremental_mapping(db, images, work / "sparse",
                                          options=mapper or pycolmap.IncrementalPipelineOptions())
    best = max(models.values(), key=lambda r: r.num_reg_images())
    out.mkdir(parents=True, exist_ok=True)
    best.write_text(str(out))
    return best, len(models), names, time.time() - t0
