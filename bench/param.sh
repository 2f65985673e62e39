#!/usr/bin/env bash
# Parameterisation (issue 6): fresco's unwrap against xatlas (pip `xatlas`) on the same
# meshes (sphere, torus, double torus, synthetic temple, a 200,704-face torus, and the Poisson
# mesh of templeSparseRing's sparse points in datasets/), same atlas resolution and padding.
# Quality is measured by the same code for both (fresco_param::metrics; on xatlas's OBJ after
# welding exact duplicate vertices): L2 stretch, flips, overlaps, utilisation, charts.
# Times: fresco's unwrap call (no file I/O) against xatlas's add_mesh + generate (no file
# I/O); interleaved fresco / xatlas (A B A B), RUNS each; medians.
#
# fresco runs through the release example `unwrap_file` (the same library calls as `fresco
# unwrap`), which builds in a few minutes where the whole CLI in release takes many more.
# xatlas is called as users call it (resolution + padding, its own density estimate); it
# returns its own atlas width x height and may make several atlases: its utilisation is over
# all of them (bench/param_xatlas.py).
#
#   bench/param.sh                 # RUNS=3, release build first
#   QUICK=1 bench/param.sh         # 1 run each (< 5 minutes once built)
#   NO_BUILD=1 RUNS=5 ATLAS=2048 GUTTER=4 bench/param.sh
set -euo pipefail
cd "$(dirname "$0")/.."
RUNS=${RUNS:-3}
if [ "${QUICK:-0}" = 1 ]; then RUNS=1; fi
ATLAS=${ATLAS:-1024}
GUTTER=${GUTTER:-2}
PYTHON=${PYTHON:-$(bench/venv.sh xatlas)}
EX=target/release/examples
OUT=bench/out/param
mkdir -p "$OUT"
if [ "${NO_BUILD:-0}" != 1 ]; then
    cargo build --release -p fresco-param --example unwrap_file --example bench_meshes
fi
"$EX"/bench_meshes "$OUT" > /dev/null
MESHES="sphere torus double_torus temple torus_200k"
if [ -f datasets/poisson/temple_sparse_poisson.ply ]; then
    cp datasets/poisson/temple_sparse_poisson.ply "$OUT/temple_poisson.ply"
    MESHES="sphere torus double_torus temple temple_poisson torus_200k"
fi
: > "$OUT/runs.jsonl"
echo "start: $(date -u '+%Y-%m-%d %H:%M UTC'), load average: $(cut -d' ' -f1-3 /proc/loadavg)"
for name in $MESHES; do
    for i in $(seq 1 "$RUNS"); do
        "$EX"/unwrap_file "$OUT/$name.ply" "$OUT/$name.fresco.obj" "$ATLAS" "$GUTTER" \
            | python3 -c "import json,sys; d=json.load(sys.stdin); d['tool']='fresco'; d['mesh']='$name'; print(json.dumps(d))" >> "$OUT/runs.jsonl"
        x=$("$PYTHON" bench/param_xatlas.py "$OUT/$name.ply" "$OUT/$name.xatlas.obj" "$ATLAS" "$GUTTER")
        m=$("$EX"/unwrap_file --measure "$OUT/$name.xatlas.obj")
        python3 -c "import json,sys; x=json.loads(sys.argv[1]); m=json.loads(sys.argv[2]); x['metrics']=m['metrics']; x['tool']='xatlas'; x['mesh']='$name'; print(json.dumps(x))" "$x" "$m" >> "$OUT/runs.jsonl"
    done
done
echo "end: $(date -u '+%Y-%m-%d %H:%M UTC'), release, atlas $ATLAS, gutter $GUTTER, runs $RUNS, load average: $(cut -d' ' -f1-3 /proc/loadavg)"
python3 - "$OUT/runs.jsonl" <<'PY'
import json, statistics, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
print("| mesh | faces | tool | atlases | charts | flipped | overlaps | L2 stretch | Linf stretch | angle dist. deg | utilisation | median s | xatlas s / fresco s |")
print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
for mesh in dict.fromkeys(r["mesh"] for r in rows):
    f = [r for r in rows if r["mesh"] == mesh and r["tool"] == "fresco"]
    x = [r for r in rows if r["mesh"] == mesh and r["tool"] == "xatlas"]
    tf = statistics.median(r["seconds"] for r in f)
    tx = statistics.median(r["seconds"] for r in x)
    for tool, rs, t in (("fresco", f, tf), ("xatlas", x, tx)):
        m = rs[-1]["metrics"]
        if tool == "xatlas":
            # Each atlas' UVs were shifted by its index along u: the measured area is the
            # sum over atlases.
            atlases = f"{rs[-1]['atlas_count']} ({rs[-1]['width']}x{rs[-1]['height']})"
            util = m["utilisation"] / rs[-1]["atlas_count"]
        else:
            atlases = f"{rs[-1]['report']['atlases']}"
            util = m["utilisation"]
        ratio = f"{tx / tf:.2f}" if tool == "fresco" else ""
        print(f"| {mesh} | {m['faces']} | {tool} | {atlases} | {m['charts']} | {m['flipped']} | {m['overlapping_pairs']} | "
              f"{m['l2_stretch']:.4f} | {m['linf_stretch']:.3f} | {m['angle_distortion_deg']:.2f} | {util:.3f} | {t:.3f} | {ratio} |")
PY
