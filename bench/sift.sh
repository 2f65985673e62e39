#!/usr/bin/env bash
# Issue 3 benchmark: fresco features vs OpenCV SIFT (detect + describe) on the 16
# templeSparseRing photos (640x480) and the 11 sceaux_castle photos (1600x1202).
# Interleaved runs (fresco, OpenCV, fresco, OpenCV, ...), medians of RUNS (default 3).
# Both sides: default settings (2x up-sampled first octave, 3 intervals, contrast 0.04, edge 10),
# all keypoints kept (fresco --max-features 0, OpenCV nfeatures=0), default threads (all cores).
# Times are measured inside each tool and include reading the photos; fresco's also includes
# writing the feature files.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-/work/venv/bin/python}
RUNS=${RUNS:-3}
OUT=bench/out/sift
mkdir -p "$OUT"
cargo build --release -p fresco >&2
FRESCO=${CARGO_TARGET_DIR:-target}/release/fresco

median() { sort -g | awk '{a[NR]=$1} END {m=(NR%2)?a[(NR+1)/2]:(a[NR/2]+a[NR/2+1])/2; print m}'; }

echo "| set | tool | photos | keypoints | median s | keypoints/s |"
echo "|---|---|---|---|---|---|"
for set in templeSparseRing:datasets/templeSparseRing sceaux:datasets/sceaux_castle/images; do
  name=${set%%:*}; dir=${set#*:}
  : > "$OUT/$name.fresco"; : > "$OUT/$name.opencv"
  for i in $(seq "$RUNS"); do
    rm -rf "$OUT/ws_$name"
    $FRESCO --json features "$dir" -o "$OUT/ws_$name" --max-features 0 > "$OUT/$name.fresco.json"
    "$PYTHON" -c "import json,sys; d=json.load(open(sys.argv[1])); print(d['seconds'], d['keypoints'], d['images'])" "$OUT/$name.fresco.json" >> "$OUT/$name.fresco"
    "$PYTHON" bench/sift_opencv.py "$dir" > "$OUT/$name.opencv.json"
    "$PYTHON" -c "import json,sys; d=json.load(open(sys.argv[1])); print(d['seconds'], d['keypoints'], d['images'])" "$OUT/$name.opencv.json" >> "$OUT/$name.opencv"
  done
  for tool in fresco opencv; do
    s=$(cut -d' ' -f1 "$OUT/$name.$tool" | median)
    k=$(tail -1 "$OUT/$name.$tool" | cut -d' ' -f2)
    n=$(tail -1 "$OUT/$name.$tool" | cut -d' ' -f3)
    label=$([ $tool = fresco ] && echo fresco || echo "OpenCV $("$PYTHON" -c 'import cv2; print(cv2.__version__)') SIFT")
    printf "| %s | %s | %s | %s | %.3f | %.0f |\n" "$name" "$label" "$n" "$k" "$s" "$(echo "$k / $s" | bc -l)"
    eval "med_$tool=$s"
  done
  printf "| %s | OpenCV / fresco time | | | %.2fx | |\n" "$name" "$(echo "$med_opencv / $med_fresco" | bc -l)"
done
echo
echo "load average: $(cut -d' ' -f1-3 /proc/loadavg), $(date -u +%Y-%m-%d), RUNS=$RUNS"
