#!/usr/bin/env bash
# `fresco mesh` end to end (issue 5; bench/poisson.sh times the Poisson call alone) against
# the same chain in Open3D 0.20, on the same oriented clouds of the sphere, torus and blob
# (sampled by fresco_datasets through the poisson_bench example, written as PLY):
#   fresco:  fresco --threads 2 mesh <ws> --points cloud --depth D  (its defaults: point
#            weight 4, trim one below the median density, clean-up, decimation to 200k faces)
#   Open3D:  create_from_point_cloud_poisson(depth D, n_threads=2), vertices below the
#            median density minus 1 removed, simplify_quadric_decimation to 200k faces
#            (bench/mesh_reference.py)
# Interleaved fresco / Open3D, RUNS each. Time: fresco's stage seconds summed from its JSON
# summary and Open3D's chain, both without file reading/writing; plus fresco's whole process
# (PLY in and out included). Distances to the ground truth with fresco's metrics
# (mesh_distance example: 400k area samples a side, exact point-triangle distances).
# Then decimation alone: the 1.31M-face blob (20 * 4^8) to 100k faces, fresco's decimate
# (decimate_bench example) against Open3D's simplify_quadric_decimation on the same mesh,
# time and Hausdorff / Chamfer distance of each output to the input (same metric).
#
#   bench/mesh.sh                                    # Open3D from bench/.venv (bench/venv.sh; or PYTHON=...)
#   RUNS=5 DEPTH=9 POINTS=200000 SHAPES="sphere torus blob" bench/mesh.sh
set -euo pipefail
cd "$(dirname "$0")/.."
RUNS=${RUNS:-3}
DEPTH=${DEPTH:-9}
POINTS=${POINTS:-200000}
FACES=${FACES:-200000}
SHAPES=${SHAPES:-"sphere torus blob"}
PYTHON=${PYTHON:-$(bench/venv.sh open3d)}
OUT=bench/out/mesh
mkdir -p "$OUT"
cargo build --release -p fresco
cargo build --release -p fresco-surface --example poisson_bench --example mesh_distance \
    --example decimate_bench
BIN=target/release
RUNS_FILE="$OUT/runs.jsonl"
: > "$RUNS_FILE"
rec() { # wraps the last JSON line on stdin: {"shape", "tool", "kind", "r": line}
    printf '{"shape": "%s", "tool": "%s", "kind": "%s", "r": %s}\n' "$1" "$2" "$3" "$(tail -n 1)"
}
for shape in $SHAPES; do
    cloud="$OUT/${shape}_cloud.ply"
    gt="$OUT/${shape}_gt.ply"
    ws="$OUT/ws_$shape"
    mkdir -p "$ws"
    "$BIN/examples/poisson_bench" "$shape" "$POINTS" 8 0 --points-out "$cloud" --gt-out "$gt"
    for _ in $(seq 1 "$RUNS"); do
        t0=$(date +%s.%N)
        "$BIN/fresco" --threads 2 --quiet --json mesh "$ws" --points "$cloud" --depth "$DEPTH" \
            --faces "$FACES" > "$OUT/fresco_$shape.json"
        t1=$(date +%s.%N)
        "$PYTHON" - "$OUT/fresco_$shape.json" "$t0" "$t1" <<'PY' | rec "$shape" fresco time >> "$RUNS_FILE"
import json, sys
j = json.load(open(sys.argv[1]))
j = j.get("result", j)
stages = sum(j[k] for k in ("seconds_normals", "seconds_poisson", "seconds_trim",
                            "seconds_cleanup", "seconds_decimate"))
print(json.dumps({"seconds": stages, "seconds_process": float(sys.argv[3]) - float(sys.argv[2]),
                  "seconds_poisson": j["seconds_poisson"], "seconds_decimate": j["seconds_decimate"],
                  "faces": j["faces"]}))
PY
        "$PYTHON" bench/mesh_reference.py mesh "$cloud" "$OUT/open3d_$shape.ply" "$DEPTH" "$FACES" \
            | rec "$shape" open3d time >> "$RUNS_FILE"
    done
    "$BIN/examples/mesh_distance" "$ws/mesh.ply" "$gt" | rec "$shape" fresco dist >> "$RUNS_FILE"
    "$BIN/examples/mesh_distance" "$OUT/open3d_$shape.ply" "$gt" | rec "$shape" open3d dist >> "$RUNS_FILE"
done
blob="$OUT/blob_1m.ply"
for i in $(seq 1 "$RUNS"); do
    if [ "$i" = 1 ]; then write=(--input-out "$blob" --output-out "$OUT/decimated_fresco.ply"); else write=(); fi
    "$BIN/examples/decimate_bench" 100000 "${write[@]}" | rec blob fresco decimate >> "$RUNS_FILE"
    "$PYTHON" bench/mesh_reference.py decimate "$blob" "$OUT/decimated_open3d.ply" 100000 \
        | rec blob open3d decimate >> "$RUNS_FILE"
done
"$BIN/examples/mesh_distance" "$OUT/decimated_open3d.ply" "$blob" 1000000 | rec blob open3d decdist >> "$RUNS_FILE"
python3 - "$RUNS_FILE" "$DEPTH" "$POINTS" "$RUNS" "$FACES" <<'PY'
import json, statistics, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
depth, points, runs, faces = sys.argv[2:6]
med = statistics.median
def sel(shape, tool, kind):
    return [r["r"] for r in rows if r["shape"] == shape and r["tool"] == tool and r["kind"] == kind]
print(f"depth {depth}, {points} points per cloud, {faces}-face budget, {runs} interleaved runs per tool, medians")
print()
print("| shape | fresco s (stages) | fresco s (process) | Open3D s | fresco/Open3D | fresco Chamfer (% diag) "
      "| Open3D Chamfer (% diag) | fresco Hausdorff (% diag) | Open3D Hausdorff (% diag) | fresco faces "
      "| Open3D faces | fresco closed manifold, genus |")
print("|---|---|---|---|---|---|---|---|---|---|---|---|")
for shape in dict.fromkeys(r["shape"] for r in rows if r["kind"] == "time"):
    f, o = sel(shape, "fresco", "time"), sel(shape, "open3d", "time")
    fd, od = sel(shape, "fresco", "dist")[0], sel(shape, "open3d", "dist")[0]
    fs, fp, os_ = med(r["seconds"] for r in f), med(r["seconds_process"] for r in f), med(r["seconds"] for r in o)
    print(f"| {shape} | {fs:.2f} | {fp:.2f} | {os_:.2f} | {fs / os_:.2f}x | {100 * fd['chamfer_relative']:.4f} | "
          f"{100 * od['chamfer_relative']:.4f} | {100 * fd['hausdorff_relative']:.3f} | "
          f"{100 * od['hausdorff_relative']:.3f} | {fd['faces']} | {od['faces']} | "
          f"{fd['closed_manifold']}, {fd['genus']} |")
fdec, odec = sel("blob", "fresco", "decimate"), sel("blob", "open3d", "decimate")
if fdec:
    od = sel("blob", "open3d", "decdist")[0]
    cpu = [r["cpu_seconds"] for r in fdec if r.get("cpu_seconds") is not None]
    print()
    print("| decimation, blob | faces | median s | fresco CPU s | Hausdorff (% diag) | Chamfer (% diag) |")
    print("|---|---|---|---|---|---|")
    print(f"| fresco (quadric edge collapse) | {fdec[0]['faces_before']} -> {fdec[0]['faces_after']} | "
          f"{med(r['seconds'] for r in fdec):.2f} | {med(cpu) if cpu else float('nan'):.2f} | "
          f"{100 * fdec[0]['hausdorff_relative']:.4f} | {100 * fdec[0]['chamfer_relative']:.5f} |")
    print(f"| Open3D simplify_quadric_decimation | {odec[0]['faces_before']} -> {odec[0]['faces_after']} | "
          f"{med(r['seconds'] for r in odec):.2f} | | {100 * od['hausdorff_relative']:.4f} | "
          f"{100 * od['chamfer_relative']:.5f} |")
PY
