#!/usr/bin/env bash
# templeSparseRing with the true calibration given to both tools (issue 4's accuracy without
# the focal length and principal point to estimate): fresco `reconstruct --focal-file K.txt
# --camera-model PINHOLE --single-camera` against pycolmap with a fixed PINHOLE camera, both
# scored by `fresco eval poses` against templeSR_par.txt.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-$(bench/venv.sh colmap)}
OUT=bench/out/temple_known_k
rm -rf "$OUT" && mkdir -p "$OUT"
cargo build --release -p fresco
printf "1520.4 0 302.32\n0 1525.9 246.87\n0 0 1\n" > "$OUT/K.txt"
PAR=datasets/templeSparseRing/templeSR_par.txt
echo "start: $(date -u "+%Y-%m-%d %H:%M UTC"), load average: $(cut -d" " -f1-3 /proc/loadavg)"
target/release/fresco -q reconstruct datasets/templeSparseRing --focal-file "$OUT/K.txt" \
    --camera-model PINHOLE --single-camera -o "$OUT/fresco"
echo "fresco, known K:"
target/release/fresco eval poses "$OUT/fresco/sparse/0" --gt "$PAR"
"$PYTHON" bench/temple_known_k.py datasets/templeSparseRing "$OUT/colmap" 2>/dev/null
echo "COLMAP, known K:"
target/release/fresco eval poses "$OUT/colmap" --gt "$PAR"
"$PYTHON" bench/temple_known_k_common.py "$OUT/fresco/sparse/0" "$OUT/colmap" "$OUT/fresco_common"
echo "fresco, known K, on the images COLMAP registered:"
target/release/fresco eval poses "$OUT/fresco_common" --gt "$PAR"
