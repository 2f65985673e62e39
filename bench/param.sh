#!/usr/bin/env bash
# Parameterisation (issue 6): `fresco unwrap` against xatlas (pip `xatlas`) on the same
# meshes (sphere, torus, double torus, temple, a 200,704-face torus), same atlas size and
# gutter. Quality is measured by the same code for both (`fresco unwrap --measure`, i.e.
# fresco_param::metrics on xatlas's OBJ): L2 stretch, flips, overlaps, utilisation, charts.
# Times: fresco's unwrap call (no file I/O) against xatlas's add_mesh + generate (no file
# I/O); interleaved fresco / xatlas, RUNS each; medians.
#
#   bench/param.sh                 # PYTHON=/work/venv/bin/python by default
#   RUNS=5 ATLAS=2048 GUTTER=4 bench/param.sh
set -euo pipefail
cd "$(dirname "$0")/.."
RUNS=${RUNS:-3}
ATLAS=${ATLAS:-1024}
GUTTER=${GUTTER:-2}
PYTHON=${PYTHON:-/work/venv/bin/python}
# PROFILE=dev runs the test-profile build (opt-level 2) when a release build is not at hand.
PROFILE=${PROFILE:-release}
OUT=bench/out/param
mkdir -p "$OUT"
if [ "$PROFILE" = release ]; then
    cargo build --release -p fresco && cargo build --release -p fresco-param --example bench_meshes
    BIN=target/release
else
    cargo build -p fresco && cargo build -p fresco-param --example bench_meshes
    BIN=target/debug
fi
"$BIN"/examples/bench_meshes "$OUT" > /dev/null
: > "$OUT/runs.jsonl"
for name in sphere torus double_torus temple torus_200k; do
    for i in $(seq 1 "$RUNS"); do
        "$BIN"/fresco --quiet --json unwrap "$OUT/$name.ply" -o "$OUT/$name.fresco.obj" \
            --atlas "$ATLAS" --gutter "$GUTTER" --png "$OUT/$name.fresco.png" \
            | python3 -c "import json,sys; d=json.load(sys.stdin); d['tool']='fresco'; d['mesh']='$name'; print(json.dumps(d))" >> "$OUT/runs.jsonl"
        x=$("$PYTHON" bench/param_xatlas.py "$OUT/$name.ply" "$OUT/$name.xatlas.obj" "$ATLAS" "$GUTTER")
        m=$("$BIN"/fresco --quiet --json unwrap --measure "$OUT/$name.xatlas.obj")
        python3 -c "import json,sys; x=json.loads(sys.argv[1]); m=json.loads(sys.argv[2]); x['metrics']=m['metrics']; x['tool']='xatlas'; x['mesh']='$name'; print(json.dumps(x))" "$x" "$m" >> "$OUT/runs.jsonl"
    done
done
echo "profile: $PROFILE, atlas $ATLAS, gutter $GUTTER, runs $RUNS, load average: $(cut -d' ' -f1-3 /proc/loadavg)"
python3 - "$OUT/runs.jsonl" <<'PY'
import json, statistics, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
print(f"| mesh | faces | tool | charts | flipped | overlaps | L2 stretch | Linf stretch | angle dist. deg | utilisation | median s | time ratio xatlas/fresco |")
print("|---|---|---|---|---|---|---|---|---|---|---|---|")
for mesh in dict.fromkeys(r["mesh"] for r in rows):
    f = [r for r in rows if r["mesh"] == mesh and r["tool"] == "fresco"]
    x = [r for r in rows if r["mesh"] == mesh and r["tool"] == "xatlas"]
    tf = statistics.median(r["seconds"] for r in f)
    tx = statistics.median(r["seconds"] for r in x)
    for tool, rs, t in (("fresco", f, tf), ("xatlas", x, tx)):
        m = rs[-1]["metrics"]
        extra = ""
        if tool == "xatlas":
            extra = f" ({rs[-1]['atlas_count']} atlas, {rs[-1]['width']}x{rs[-1]['height']})"
        ratio = f"{tx / tf:.2f}" if tool == "fresco" else ""
        print(f"| {mesh} | {m['faces']} | {tool}{extra} | {m['charts']} | {m['flipped']} | {m['overlapping_pairs']} | "
              f"{m['l2_stretch']:.4f} | {m['linf_stretch']:.3f} | {m['angle_distortion_deg']:.2f} | {m['utilisation']:.3f} | {t:.3f} | {ratio} |")
PY
