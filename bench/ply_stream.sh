#!/usr/bin/env bash
# Issue 2: streaming PLY. Writes a 10M-vertex (20M-triangle) binary little-endian PLY with
# fresco's streaming writer, then reads it back with fresco's streaming reader and with the
# Python plyfile package (which loads the whole file), each under /usr/bin/time -v for the
# peak resident memory. Prints a markdown table.
#
#   bench/ply_stream.sh [grid side, default 3163 -> 10,004,569 vertices]
set -euo pipefail
cd "$(dirname "$0")/.."
N=${1:-3163}
PYTHON=${PYTHON:-$(bench/venv.sh plyfile)}
OUT=bench/out/ply_stream
mkdir -p "$OUT"
cargo build --release -q -p fresco-core --example ply_stream
BIN=target/release/examples/ply_stream
FILE="$OUT/grid_${N}.ply"

peak_mb() { awk '/Maximum resident set size/ {printf "%.1f", $6/1024}' "$1"; }

/usr/bin/time -v "$BIN" write "$FILE" "$N" le >"$OUT/write.json" 2>"$OUT/write.time"
echo "load average: $(cut -d' ' -f1-3 /proc/loadavg)"
echo
echo "| tool | task | vertices | faces | file MB | seconds | MB/s | peak RSS MB |"
echo "|---|---|---|---|---|---|---|---|"
row() { # tool task json timefile
    "$PYTHON" - "$1" "$2" "$3" "$(peak_mb "$4")" <<'PY'
import json, sys
tool, task, path, peak = sys.argv[1:5]
d = json.load(open(path))
print(f"| {tool} | {task} | {d['vertices']:,} | {d['faces']:,} | {d['bytes']/1e6:.0f} | {d['seconds']:.2f} | {d['mb_per_s']:.0f} | {peak} |")
PY
}
row fresco "stream write (binary LE)" "$OUT/write.json" "$OUT/write.time"
for run in 1 2 3; do
    /usr/bin/time -v "$BIN" read "$FILE" >"$OUT/read$run.json" 2>"$OUT/read$run.time"
    if [[ -x "$PYTHON" ]] && "$PYTHON" -c "import plyfile" 2>/dev/null; then
        /usr/bin/time -v "$PYTHON" - "$FILE" >"$OUT/plyfile$run.json" 2>"$OUT/plyfile$run.time" <<'PY'
import json, os, sys, time
import plyfile
t = time.time()
ply = plyfile.PlyData.read(sys.argv[1])
v = ply["vertex"].data; f = ply["face"].data
z = float(v["z"].sum()); n = len(f)
s = time.time() - t
b = os.path.getsize(sys.argv[1])
print(json.dumps({"vertices": len(v), "faces": n, "bytes": b, "seconds": s, "mb_per_s": b / 1e6 / s}))
PY
    fi
done
for run in 1 2 3; do row fresco "stream read, run $run" "$OUT/read$run.json" "$OUT/read$run.time"; done
for run in 1 2 3; do
    [[ -f "$OUT/plyfile$run.json" ]] && row "plyfile $("$PYTHON" -c 'import plyfile,importlib.metadata as m;print(m.version("plyfile"))')" "load whole file, run $run" "$OUT/plyfile$run.json" "$OUT/plyfile$run.time"
done
rm -f "$FILE"
