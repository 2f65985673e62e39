#!/usr/bin/env bash
# Rasteriser throughput (issue 2): a 1M-triangle torus at 1920x1080, depth + face id per
# pixel (fresco raster::visibility) and a vertex-coloured render (raster::render), against
# Open3D's RaycastingScene (Embree) casting one ray per pixel centre of the same view.
# Runs interleaved fresco / Open3D, 5 each, and prints medians and ratios.
#
#   bench/raster.sh            # Open3D from bench/.venv (bench/venv.sh; or PYTHON=/path/to/python)
#   RUNS=7 bench/raster.sh
set -euo pipefail
cd "$(dirname "$0")/.."
RUNS=${RUNS:-5}
PYTHON=${PYTHON:-$(bench/venv.sh open3d)}
OUT=bench/out/raster
mkdir -p "$OUT"
cargo build --release -p fresco-datasets --example raster_bench
: > "$OUT/runs.jsonl"
for i in $(seq 1 "$RUNS"); do
    # One timed run per process, after one warm-up run in the same process (page cache,
    # allocator); the sample map is built once per process and reported apart.
    target/release/examples/raster_bench 2 0 | tail -n 1 >> "$OUT/runs.jsonl"
    if "$PYTHON" -c "import open3d" 2>/dev/null; then
        "$PYTHON" bench/raster_reference.py 2 | tail -n 1 >> "$OUT/runs.jsonl"
    fi
done
python3 - "$OUT/runs.jsonl" <<'PY'
import json, statistics, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
fr = [r for r in rows if r["tool"] == "fresco"]
o3 = [r for r in rows if r["tool"] == "open3d"]
med = lambda rs, k: statistics.median(r[k] for r in rs)
tris, pixels = fr[0]["triangles"], fr[0]["pixels"]
vis, ren, smap = med(fr, "visibility_s"), med(fr, "render_s"), med(fr, "sample_map_s")
print(f"runs: {len(fr)} fresco, {len(o3)} open3d; {tris} triangles, {pixels} pixels, "
      f"{fr[0]['covered_pixels']} covered (fresco)"
      + (f", {o3[0]['covered_pixels']} (open3d)" if o3 else ""))
print(f"| tool | task | median s | triangles/s | pixels/s |")
print(f"|---|---|---|---|---|")
print(f"| fresco | sample map (once per camera) | {smap:.3f} | | {pixels / smap:.3g} |")
print(f"| fresco | visibility (depth + face id) | {vis:.3f} | {tris / vis:.3g} | {pixels / vis:.3g} |")
print(f"| fresco | render (vertex colours) + visibility | {ren:.3f} | {tris / ren:.3g} | {pixels / ren:.3g} |")
if o3:
    cast = med(o3, "total_s")
    print(f"| Open3D 0.20 RaycastingScene | BVH build + cast (depth + face id) | {cast:.3f} | {tris / cast:.3g} | {pixels / cast:.3g} |")
    print(f"ratio Open3D / fresco visibility time: {cast / vis:.2f}x")
PY
