"""For bench/temple_known_k.sh: mean track length of two COLMAP text models, and a copy of the
first model restricted to the images the second registered (poses only, for `fresco eval
poses` on the images both tools registered). Usage: temple_known_k_common.py <fresco model>
<colmap model> <out dir>."""
import sys
from pathlib import Path


def track_length(model):
    n = s = 0
    for line in (Path(model) / "points3D.txt").read_text().splitlines():
        if line.startswith("#") or not line.strip():
            continue
        n += 1
        s += (len(line.split()) - 8) // 2
    return s / max(n, 1), n


def image_lines(model):
    lines = [l for l in (Path(model) / "images.txt").read_text().splitlines() if not l.startswith("#")]
    return [(lines[i], lines[i + 1] if i + 1 < len(lines) else "") for i in range(0, len(lines), 2)
            if lines[i].strip()]


fresco, colmap, out = sys.argv[1:4]
names = {h.split()[9] for h, _ in image_lines(colmap)}
out = Path(out)
out.mkdir(parents=True, exist_ok=True)
(out / "cameras.txt").write_text((Path(fresco) / "cameras.txt").read_text())
kept = [h for h, _ in image_lines(fresco) if h.split()[9] in names]
(out / "images.txt").write_text("".join(f"{h}\n\n" for h in kept))
(out / "points3D.txt").write_text("")
for tool, m in (("fresco", fresco), ("COLMAP", colmap)):
    tl, n = track_length(m)
    print(f"{tool}: {n} points, mean track length {tl:.2f}")
print(f"fresco restricted to the {len(kept)} images COLMAP registered: {out}")
