"""Builds datasets/sceaux_castle/ from the full-size photo set in ../shared/datasets/:
downscales every photo to at most 1600 px on its long side (Lanczos), keeps its EXIF block
(FocalLength and FocalLengthIn35mmFilm give the focal priors; PixelX/YDimension are set to
the new size), scales K.txt to the new size and copies Readme.txt (credit) unchanged.

    /work/venv/bin/python datasets/prepare_sceaux.py [SOURCE_DIR]

Pixel-centre convention of K.txt: openMVG (where K.txt comes from) and OpenCV put pixel
centres on integers, the top-left pixel's centre at (0, 0). Resampling by a factor s maps the
continuous coordinate u (top-left corner of the image at -0.5) to (u + 0.5) * s - 0.5, so
    f' = s * f,    c' = (c + 0.5) * s - 0.5
with s = new size / old size per axis (the two differ slightly because sizes are rounded).
The written K.txt keeps the integer-centre convention; fresco adds 0.5 to cx and cy when it
reads it (fresco_datasets::real).
"""

import shutil
import sys
from pathlib import Path

from PIL import Image

MAX_SIDE = 1600
EXIF_IFD = 0x8769
PIXEL_X_DIMENSION = 40962
PIXEL_Y_DIMENSION = 40963


def main():
    here = Path(__file__).resolve().parent
    source = Path(sys.argv[1]) if len(sys.argv) > 1 else here.parent.parent / "shared/datasets/sceaux_castle"
    source = source if source.exists() else Path("/work/shared/datasets/sceaux_castle")
    out = here / "sceaux_castle"
    (out / "images").mkdir(parents=True, exist_ok=True)
    sizes = set()
    for src in sorted((source / "images").glob("*.JPG")):
        im = Image.open(src)
        w, h = im.size
        s = MAX_SIDE / max(w, h)
        nw, nh = (round(w * s), round(h * s)) if s < 1 else (w, h)
        sizes.add(((w, h), (nw, nh)))
        exif = im.getexif()
        exif.get_ifd(EXIF_IFD)[PIXEL_X_DIMENSION] = nw
        exif.get_ifd(EXIF_IFD)[PIXEL_Y_DIMENSION] = nh
        small = im.resize((nw, nh), Image.Resampling.LANCZOS)
        tmp = out / "images" / (src.name + ".tmp")
        small.save(tmp, "JPEG", quality=95, exif=exif.tobytes())
        tmp.replace(out / "images" / src.name)
        print(f"{src.name}: {w}x{h} -> {nw}x{nh}")
    if len(sizes) != 1:
        sys.exit(f"photos of different sizes {sizes}: one K.txt cannot describe them")
    ((w, h), (nw, nh)), = sizes
    sx, sy = nw / w, nh / h
    rows = [[float(v) for v in line.split()] for line in (source / "images/K.txt").read_text().splitlines() if line.strip()]
    k = [row[:] for row in rows]
    k[0][0], k[0][1], k[0][2] = rows[0][0] * sx, rows[0][1] * sx, (rows[0][2] + 0.5) * sx - 0.5
    k[1][1], k[1][2] = rows[1][1] * sy, (rows[1][2] + 0.5) * sy - 0.5
    (out / "images/K.txt").write_text("".join(" ".join(f"{v:.10g}" for v in row) + "\n" for row in k))
    shutil.copyfile(source / "Readme.txt", out / "Readme.txt")
    print("K.txt:", k)


if __name__ == "__main__":
    main()
