#!/usr/bin/env bash
# Screened Poisson reconstruction (issue 5): fresco_surface::reconstruct (through the
# poisson_bench example) against Open3D 0.20's create_from_point_cloud_poisson (PoissonRecon
# inside, n_threads=2) on the same oriented clouds of 200k points sampled from the sphere and
# torus test shapes, at depths 8 and 9. Interleaved fresco / Open3D, RUNS each; medians of
# the reconstruction time (input reading excluded on both sides) and the Chamfer distance of
# each output to the ground-truth mesh, as a fraction of its bounding-box diagonal.
#
#   bench/poisson.sh                 # needs Open3D in /work/venv (or PYTHON=/path/to/python)
#   RUNS=5 SHAPES="sphere torus blob" DEPTHS="8 9" bench/poisson.sh
set -euo pipefail
cd "$(dirname "$0")/.."
RUNS=${RUNS:-3}
SHAPES=${SHAPES:-"sphere torus"}
DEPTHS=${DEPTHS:-"8 9"}
POINTS=${POINTS:-200000}
PYTHON=${PYTHON:-/work/venv/bin/python}
OUT=bench/out/poisson
mkdir -p "$OUT"
cargo build --release -p fresco-surface --example poisson_bench
BIN=target/release/examples/poisson_bench
: > "$OUT/runs.jsonl"
for shape in $SHAPES; do
    # Cloud and ground truth once per shape (0 reconstructions).
    "$BIN" "$shape" "$POINTS" 8 0 --points-out "$OUT/$shape.ply" --gt-out "$OUT/${shape}_gt.ply"
    for depth in $DEPTHS; do
        for i in $(seq 1 "$RUNS"); do
            line=$("$BIN" "$shape" "$POINTS" "$depth" 1 --mesh-out "$OUT/${shape}_${depth}_fresco.ply" | tail -n 1)
            secs=$(echo "$line" | sed -E 's/.*depth [0-9]+: ([0-9.]+) s.*/\1/')
            echo "{\"tool\": \"fresco\", \"shape\": \"$shape\", \"depth\": $depth, \"seconds\": $secs}" >> "$OUT/runs.jsonl"
            "$PYTHON" bench/poisson_reference.py open3d "$OUT/$shape.ply" "$depth" "$OUT/${shape}_${depth}_open3d.ply" \
                | tail -n 1 | sed -E "s/^\{/{\"shape\": \"$shape\", /" >> "$OUT/runs.jsonl"
        done
        for tool in fresco open3d; do
            "$PYTHON" bench/poisson_reference.py chamfer "$OUT/${shape}_${depth}_${tool}.ply" "$OUT/${shape}_gt.ply" \
                | tail -n 1 | sed -E "s/^\{/{\"tool\": \"$tool\", \"shape\": \"$shape\", \"depth\": $depth, \"kind\": \"chamfer\", /" >> "$OUT/runs.jsonl"
        done
    done
done
python3 - "$OUT/runs.jsonl" "$POINTS" <<'PY'
import json, statistics, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
times = [r for r in rows if "seconds" in r]
ch = {(r["tool"], r["shape"], r["depth"]): r["chamfer_fraction"] for r in rows if r.get("kind") == "chamfer"}
keys = sorted({(r["shape"], r["depth"]) for r in times})
print(f"{sys.argv[2]} points per cloud; runs per cell: "
      f"{len([r for r in times if r['tool'] == 'fresco']) // max(1, len(keys))}")
print("| shape | depth | fresco median s | Open3D median s | fresco / Open3D | fresco Chamfer (% diag) | Open3D Chamfer (% diag) |")
print("|---|---|---|---|---|---|---|")
for shape, depth in keys:
    f = statistics.median(r["seconds"] for r in times if r["tool"] == "fresco" and r["shape"] == shape and r["depth"] == depth)
    o = statistics.median(r["seconds"] for r in times if r["tool"] == "open3d" and r["shape"] == shape and r["depth"] == depth)
    print(f"| {shape} | {depth} | {f:.3f} | {o:.3f} | {f / o:.2f}x | "
          f"{100 * ch[('fresco', shape, depth)]:.4f} | {100 * ch[('open3d', shape, depth)]:.4f} |")
PY
