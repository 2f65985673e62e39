"""xatlas reference for bench/param.sh: unwraps a PLY with xatlas (pip `xatlas`), times
Atlas.add_mesh + generate (no file I/O), writes the result as OBJ (positions via vmapping,
per-vertex UVs) for `fresco unwrap --measure`, and prints a JSON line with the timing and
xatlas's own figures.

xatlas is called as users call it: resolution and padding given, texels per unit left for it
to estimate. Its atlases then need not be exactly resolution x resolution (it returns its own
width x height, and may make several): the UVs it returns are normalised to that size, and
each atlas' UVs are shifted by its index along u in the OBJ so that `--measure` sees charts
of different atlases apart; `--measure`'s utilisation (UV area over one unit square) is then
divided by the atlas count, i.e. utilisation over all of xatlas's atlases.

usage: param_xatlas.py <in.ply> <out.obj> <atlas_size> <gutter> [texels_per_unit]
"""
import json
import sys
import time

import numpy as np
import trimesh
import xatlas


def main():
    src, dst, atlas, gutter = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    mesh = trimesh.load(src, process=False)
    pos = np.ascontiguousarray(mesh.vertices, dtype=np.float32)
    idx = np.ascontiguousarray(mesh.faces, dtype=np.uint32)
    t0 = time.perf_counter()
    a = xatlas.Atlas()
    a.add_mesh(pos, idx)
    pack = xatlas.PackOptions()
    pack.resolution = atlas
    pack.padding = gutter
    if len(sys.argv) > 5:
        pack.texels_per_unit = float(sys.argv[5])
    a.generate(pack_options=pack)
    seconds = time.perf_counter() - t0
    vmapping, indices, uvs = a.get_mesh(0)
    atlas_of_vertex, _chart = a.get_mesh_vertex_assignment(0)
    uvs = np.array(uvs, dtype=np.float64)
    uvs[:, 0] += atlas_of_vertex.astype(np.float64)
    with open(dst, "w") as f:
        f.write("# xatlas\n")
        for v in pos[vmapping]:
            f.write("v %.9g %.9g %.9g\n" % (v[0], v[1], v[2]))
        for uv in uvs:
            f.write("vt %.9g %.9g\n" % (uv[0], uv[1]))
        for t in indices + 1:
            f.write(f"f {t[0]}/{t[0]} {t[1]}/{t[1]} {t[2]}/{t[2]}\n")
    print(json.dumps({
        "seconds": seconds,
        "atlas_count": a.atlas_count,
        "chart_count": a.chart_count,
        "width": a.width,
        "height": a.height,
        "texels_per_unit": float(a.texels_per_unit),
        "utilization": [float(a.get_utilization(i)) for i in range(a.atlas_count)],
    }))


if __name__ == "__main__":
    main()
