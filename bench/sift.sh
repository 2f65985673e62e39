#!/usr/bin/env bash
# Issue 3 benchmark: fresco SIFT vs OpenCV SIFT (detect + describe), OpenCV's default settings on
# both sides (2x up-sampled first octave, 3 intervals, contrast 0.04, edge 10, all keypoints
# kept; fresco's own default contrast is COLMAP's 0.02, which finds about twice the keypoints),
# default threads (all cores).
#
# 1. Per image (the issue's figure): templeSR0001.png (640x480) and sceaux 100_7100.JPG
#    (1600x1202). Decoding and grey conversion untimed, one untimed warm-up call per process,
#    then one timed detect+describe; 5 processes per tool, interleaved (fresco, OpenCV, ...),
#    medians. fresco: sfm/examples/sift_phases.rs (extract_features, plus its phases);
#    OpenCV: bench/sift_opencv.py --image.
#    The same on one thread each (less sensitive to other processes' load).
# 2. Per set: `fresco features` vs bench/sift_opencv.py over the 16 temple and 11 sceaux photos
#    (times measured inside each tool, photo decoding included, fresco's also writing the
#    feature files), interleaved, medians of RUNS (default 3).
#
# Usage: bench/sift.sh            (about 6 minutes on a quiet 2-core machine after the build)
#        QUICK=1 bench/sift.sh    (per-image table + one set run each: under 4 minutes)
#        NO_BUILD=1 ...           (use the binaries already in target/release)
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-$(bench/venv.sh opencv)}
QUICK=${QUICK:-0}
RUNS=${RUNS:-$([ "$QUICK" = 1 ] && echo 1 || echo 3)}
PER_IMAGE_RUNS=${PER_IMAGE_RUNS:-5}
OUT=bench/out/sift
mkdir -p "$OUT"
if [ "${NO_BUILD:-0}" != 1 ]; then
  cargo build --release -p fresco >&2
  cargo build --release -p fresco-sfm --example sift_phases >&2
fi
TARGET=${CARGO_TARGET_DIR:-target}
FRESCO=$TARGET/release/fresco
PHASES=$TARGET/release/examples/sift_phases

median() { sort -g | awk '{a[NR]=$1} END {m=(NR%2)?a[(NR+1)/2]:(a[NR/2]+a[NR/2+1])/2; print m}'; }
field() { "$PYTHON" -c "import json,sys; d=json.loads(sys.stdin.read()); print(d['$1'])"; }
CV=$("$PYTHON" -c 'import cv2; print(cv2.__version__)')

echo "Per image: detect + describe, median of $PER_IMAGE_RUNS interleaved processes (decode untimed)"
echo
echo "| image | size | fresco keypoints | OpenCV keypoints | fresco s | OpenCV $CV s | fresco / OpenCV | fresco phases (s): scale space, DoG+extrema, orientation, descriptor |"
echo "|---|---|---|---|---|---|---|---|"
for img in datasets/templeSparseRing/templeSR0001.png datasets/sceaux_castle/images/100_7100.JPG; do
  : > "$OUT/img.fresco"; : > "$OUT/img.opencv"
  for i in $(seq "$PER_IMAGE_RUNS"); do
    "$PHASES" "$img" --runs 1 > "$OUT/img.fresco.json"
    field extract_features < "$OUT/img.fresco.json" >> "$OUT/img.fresco"
    "$PYTHON" bench/sift_opencv.py --image "$img" > "$OUT/img.opencv.json"
    field seconds < "$OUT/img.opencv.json" >> "$OUT/img.opencv"
  done
  fs=$(median < "$OUT/img.fresco"); os=$(median < "$OUT/img.opencv")
  fk=$(field keypoints < "$OUT/img.fresco.json"); ok=$(field keypoints < "$OUT/img.opencv.json")
  size=$("$PYTHON" -c "import cv2,sys; h,w=cv2.imread(sys.argv[1]).shape[:2]; print(f'{w}x{h}')" "$img")
  phases=$("$PYTHON" -c "import json,sys; d=json.load(open(sys.argv[1])); print(', '.join('%.3f' % d[k] for k in ('scale_space','dog_extrema','orientation','descriptor')))" "$OUT/img.fresco.json")
  printf "| %s | %s | %s | %s | %.3f | %.3f | %.2fx | %s |\n" "$(basename "$img")" "$size" "$fk" "$ok" "$fs" "$os" "$(echo "$fs / $os" | bc -l)" "$phases"
done
echo
echo "Per image on one thread each (RAYON_NUM_THREADS=1, cv2.setNumThreads(1)): less sensitive to other load"
echo
echo "| image | fresco s | OpenCV $CV s | fresco / OpenCV |"
echo "|---|---|---|---|"
for img in datasets/templeSparseRing/templeSR0001.png datasets/sceaux_castle/images/100_7100.JPG; do
  : > "$OUT/img1.fresco"; : > "$OUT/img1.opencv"
  for i in $(seq "$PER_IMAGE_RUNS"); do
    RAYON_NUM_THREADS=1 "$PHASES" "$img" --runs 1 | field extract_features >> "$OUT/img1.fresco"
    "$PYTHON" bench/sift_opencv.py --image "$img" 1 | field seconds >> "$OUT/img1.opencv"
  done
  fs=$(median < "$OUT/img1.fresco"); os=$(median < "$OUT/img1.opencv")
  printf "| %s | %.3f | %.3f | %.2fx |\n" "$(basename "$img")" "$fs" "$os" "$(echo "$fs / $os" | bc -l)"
done
echo
echo "Per set: whole folders, median of $RUNS interleaved runs (decode included)"
echo
echo "| set | tool | photos | keypoints | median s | keypoints/s |"
echo "|---|---|---|---|---|---|"
for set in templeSparseRing:datasets/templeSparseRing sceaux:datasets/sceaux_castle/images; do
  name=${set%%:*}; dir=${set#*:}
  : > "$OUT/$name.fresco"; : > "$OUT/$name.opencv"
  for i in $(seq "$RUNS"); do
    rm -rf "$OUT/ws_$name"
    $FRESCO --json --quiet features "$dir" -o "$OUT/ws_$name" --max-features 0 --contrast-threshold 0.04 > "$OUT/$name.fresco.json"
    "$PYTHON" -c "import json,sys; d=json.load(open(sys.argv[1])); print(d['seconds'], d['keypoints'], d['images'])" "$OUT/$name.fresco.json" >> "$OUT/$name.fresco"
    "$PYTHON" bench/sift_opencv.py "$dir" > "$OUT/$name.opencv.json"
    "$PYTHON" -c "import json,sys; d=json.load(open(sys.argv[1])); print(d['seconds'], d['keypoints'], d['images'])" "$OUT/$name.opencv.json" >> "$OUT/$name.opencv"
  done
  for tool in fresco opencv; do
    s=$(cut -d' ' -f1 "$OUT/$name.$tool" | median)
    k=$(tail -1 "$OUT/$name.$tool" | cut -d' ' -f2)
    n=$(tail -1 "$OUT/$name.$tool" | cut -d' ' -f3)
    label=$([ $tool = fresco ] && echo fresco || echo "OpenCV $CV SIFT")
    printf "| %s | %s | %s | %s | %.3f | %.0f |\n" "$name" "$label" "$n" "$k" "$s" "$(echo "$k / $s" | bc -l)"
    eval "med_$tool=$s"
  done
  printf "| %s | fresco / OpenCV time | | | %.2fx | |\n" "$name" "$(echo "$med_fresco / $med_opencv" | bc -l)"
done
echo
echo "load average: $(cut -d' ' -f1-3 /proc/loadavg), $(date -u '+%Y-%m-%d %H:%M UTC'), threads $(nproc), RUNS=$RUNS, QUICK=$QUICK"
