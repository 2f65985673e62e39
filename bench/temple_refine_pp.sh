#!/usr/bin/env bash
# templeSparseRing without calibration, principal point refined in bundle adjustment by both
# tools (fresco `reconstruct --single-camera --refine-principal-point`, pycolmap with
# ba_refine_principal_point), then both with their defaults (principal point at the image
# centre), scored by `fresco eval poses` against templeSR_par.txt (true principal point
# 302.8, 247.4 in COLMAP's pixel convention).
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-$(bench/venv.sh colmap)}
OUT=bench/out/temple_refine_pp
rm -rf "$OUT" && mkdir -p "$OUT"
if [ "${NO_BUILD:-0}" != 1 ]; then cargo build --release -p fresco; fi
PAR=datasets/templeSparseRing/templeSR_par.txt
echo "start: $(date -u "+%Y-%m-%d %H:%M UTC"), load average: $(cut -d" " -f1-3 /proc/loadavg)"
for mode in refined default; do
    flag=$([ $mode = refined ] && echo --refine-principal-point || true)
    # shellcheck disable=SC2086
    target/release/fresco -q reconstruct datasets/templeSparseRing --single-camera $flag \
        -o "$OUT/fresco_$mode"
    echo "fresco, principal point $mode: camera $(tail -1 "$OUT/fresco_$mode/sparse/0/cameras.txt")"
    target/release/fresco eval poses "$OUT/fresco_$mode/sparse/0" --gt "$PAR"
done
"$PYTHON" bench/temple_refine_pp.py datasets/templeSparseRing "$OUT/colmap_refined" 2>/dev/null
target/release/fresco eval poses "$OUT/colmap_refined" --gt "$PAR"
echo "COLMAP, defaults (committed model datasets/reference/colmap/templeSparseRing):"
target/release/fresco eval poses datasets/reference/colmap/templeSparseRing --gt "$PAR"
