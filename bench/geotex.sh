#!/usr/bin/env bash
# Issue 17 benchmarks (resizing models with geometric texture, paper 002) on the 2-core
# machine: each synthetic model of fresco_datasets::geometric_texture (threaded cylinder,
# bumpy box, scaly blob; ~25k vertices) stretched 2x along one axis (z for the cylinder, x
# for the others) with the three methods (texture = paper 002, kraevoy = protective grid on
# the textured mesh, uniform). Prints, per run, the feature sizes measured on input and
# output (thread pitch = z period of the displacement; bump/scale radius along the stretch
# and across it) beside the generator's ground truth, the base-shape error, the time of
# each phase (resize = everything but the measurement) and the peak memory; writes the
# before/after pictures to bench/pictures/geotex_<model>_<method>.png (left: input, right:
# output, same scale, texture regions coloured). There is no reference
# tool (no open library does this): the anchor is the paper's timings (25k vertices:
# segmentation < 1 s, extraction 1-2 s, 25-30 EM steps of 2-5 s each, 3 GHz Core 2).
#
# Times: wall seconds of the resize (everything but the measurement) and its CPU seconds
# (user + system, all threads: what the machine's load changes least; under load rayon's
# idle workers add spinning, RAYON_NUM_THREADS=1 gives the work alone).
#
# BIG=1 also runs the million-face case: the threaded cylinder at 800 segments (1.02M faces,
# thread scaled to the same size in edges), texture method, without the measurement; prints
# its phases, wall and CPU seconds and peak memory (goal: under 60 s on 2 cores).
#
# Usage: bench/geotex.sh            (MODELS="threaded-cylinder" METHODS="texture" to narrow)
set -euo pipefail
cd "$(dirname "$0")/.."
echo "start $(date -u +%FT%TZ), load $(cut -d' ' -f1-3 /proc/loadavg)"
cargo build --release -p fresco-geotex --example geotex_bench
BENCH=target/release/examples/geotex_bench
TMP=$(mktemp -d /tmp/geotex-bench.XXXXXX)
trap 'rm -rf "$TMP"' EXIT
mkdir -p bench/pictures
MODELS=${MODELS:-"threaded-cylinder bumpy-box scaly-blob"}
METHODS=${METHODS:-"texture kraevoy uniform"}
printf '%-18s %-8s %-11s %7s %7s %7s %7s %9s %8s %8s %9s %7s %6s\n' \
    model method feature truth in out out/in base_rms resize_s resize_cpu measure_s peak_MB load
for model in $MODELS; do
    for method in $METHODS; do
        nice -n 19 /usr/bin/time -f '%M' -o "$TMP/rss" "$BENCH" "$model" "$method" \
            "bench/pictures/geotex_${model}_${method}.png" > "$TMP/run.json"
        python3 - "$TMP/run.json" "$(cat "$TMP/rss")" "$(cut -d' ' -f1 /proc/loadavg)" <<'PY'
import json, sys
run = json.load(open(sys.argv[1]))
rss, load = int(sys.argv[2]), sys.argv[3]
model, r = run["model"], run["report"]
method, m = r["method"], r["measurement"]
truth = run["truth"]
fmt = lambda x: "-" if x is None else f"{x:.4f}"
for a, b in zip(m["input"]["regions"], m["output"]["regions"]):
    if truth[0]["kind"] == "thread":
        rows = [("pitch z", a["period"][2], b["period"][2], truth[0]["pitch"])]
    else:
        # Radius (2 sigma) of the raised elements along the stretch (x) and across it (y).
        rows = [(ax, a["element_radius"][k], b["element_radius"][k], None)
                for k, ax in ((0, "radius x"), (1, "radius y"))]
    for name, i, o, t in rows:
        ratio = o / i if (i and o) else float("nan")
        print(f"{model:<18} {method:<8} {'r'+str(a['region'])+' '+name:<11} {fmt(t):>7} "
              f"{fmt(i):>7} {fmt(o):>7} {ratio:7.3f} {m['base_error']['rms']:9.2e} "
              f"{r['seconds']['resize']:8.2f} {r['cpu_seconds']['resize']:8.2f} "
              f"{r['seconds']['measurement']:9.2f} "
              f"{rss/1024:7.0f} {load:>6}")
c = r["cpu_seconds"]
print(f"{'':<18} {method:<8} phases (CPU-s): curvature {c['curvature']:.2f}, segmentation "
      f"{c['segmentation']:.2f}, extraction {c['extraction']:.2f}, grid {c['grid']:.2f}, "
      f"refinement {c['refinement']:.2f}, synthesis {c['synthesis']:.2f}, measurement "
      f"{c['measurement']:.2f}; {r['input_vertices']} -> {r['output_vertices']} vertices; "
      f"truth {truth}")
PY
    done
done
if [ "${BIG:-0}" = 1 ]; then
    nice -n 19 /usr/bin/time -f '%M' -o "$TMP/rss" "$BENCH" threaded-cylinder-1m texture \
        "$TMP/big.png" --no-measure > "$TMP/run.json"
    python3 - "$TMP/run.json" "$(cat "$TMP/rss")" "$(cut -d' ' -f1 /proc/loadavg)" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))["report"]
s, c = r["seconds"], r["cpu_seconds"]
print(f"threaded-cylinder-1m texture: {r['input_faces']} faces, {r['input_vertices']} -> "
      f"{r['output_vertices']} vertices; resize {s['resize']:.1f} s wall, {c['resize']:.1f} "
      f"CPU-s; peak {int(sys.argv[2]) / 1024:.0f} MB; load {sys.argv[3]}")
print("  phases (CPU-s): " + ", ".join(f"{k} {v:.1f}" for k, v in c.items()
                                          if k not in ("resize", "measurement")))
PY
fi
echo "end $(date -u +%FT%TZ), load $(cut -d' ' -f1-3 /proc/loadavg)"
