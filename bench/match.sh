#!/usr/bin/env bash
# Issue 3 benchmark: matching + two-view verification of the 16 templeSparseRing images
# (120 pairs, exhaustive), fresco vs OpenCV on the same features.
#
# Both tools get identical input: OpenCV SIFT keypoints and descriptors (written as a fresco
# workspace by bench/match_reference.py prepare, so the comparison is about matching and
# verification, not detection). fresco: `fresco match <ws>` (ratio 0.8, mutual check, E/F/H
# RANSAC, 4 px). OpenCV: BFMatcher knnMatch + mutual check, findEssentialMat (RANSAC 0.999,
# 4 px) + recoverPose. Interleaved (OpenCV, fresco, OpenCV, fresco, ...), median of RUNS,
# wall and CPU seconds.
# Usage: bench/match.sh [runs]   (default 5)
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-/work/venv/bin/python}
RUNS=${1:-5}

cargo build --release -p fresco
FRESCO=target/release/fresco
median() { sort -g | awk '{a[NR]=$1} END {print (NR%2 ? a[(NR+1)/2] : (a[NR/2]+a[NR/2+1])/2)}'; }

WS=$(mktemp -d)
trap 'rm -rf "$WS"' EXIT
$PYTHON bench/match_reference.py prepare "$WS"
ow=(); oc=(); fw=(); fc=()
for r in $(seq "$RUNS"); do
    line=$($PYTHON bench/match_reference.py opencv "$WS")
    echo "opencv run $r: $line"
    ow+=("$(echo "$line" | sed 's/.*"seconds": \([0-9.e-]*\).*/\1/')")
    oc+=("$(echo "$line" | sed 's/.*"cpu_seconds": \([0-9.e-]*\).*/\1/')")
    /usr/bin/time -f "%e %U %S" -o "$WS/time" $FRESCO --json match "$WS" > "$WS/summary.json"
    read -r wall user sys < "$WS/time"
    cpu=$(echo "$user + $sys" | bc)
    echo "fresco run $r: wall $wall cpu $cpu verified $(grep -o '"pairs_verified": [0-9]*' "$WS/summary.json")"
    fw+=("$wall"); fc+=("$cpu")
done
mow=$(printf '%s\n' "${ow[@]}" | median); moc=$(printf '%s\n' "${oc[@]}" | median)
mfw=$(printf '%s\n' "${fw[@]}" | median); mfc=$(printf '%s\n' "${fc[@]}" | median)
echo
echo "load average: $(cut -d' ' -f1-3 /proc/loadavg), threads: $(nproc), runs: $RUNS"
echo "| tool | median wall s | median CPU s |"
echo "|---|---|---|"
echo "| OpenCV $($PYTHON -c 'import cv2; print(cv2.__version__)') BFMatcher + findEssentialMat | $mow | $moc |"
echo "| fresco match | $mfw | $mfc |"
echo "fresco/OpenCV: wall $(echo "scale=2; $mfw / $mow" | bc), CPU $(echo "scale=2; $mfc / $moc" | bc)"
