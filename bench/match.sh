#!/usr/bin/env bash
# Issue 3 benchmark: descriptor matching throughput, then matching + two-view verification of
# the 16 templeSparseRing images (120 pairs, exhaustive), fresco vs OpenCV on the same features.
#
# 1. Throughput: OpenCV SIFT of two photos (bench/match_reference.py pair; sceaux 100_7100 and
#    100_7101 at 8192 features, temple 0001/0002 with all features) written as fresco feature
#    files; fresco's match_descriptors (ratio 0.8 + mutual check, both directions in one pass,
#    exact integer distances; sfm/examples/match_throughput.rs times every distance kernel the
#    CPU has, AVX-512 VNNI / AVX2 / portable faer f32, checks they agree, and the table's
#    fresco column is the default, fastest one) against OpenCV BFMatcher NORM_L2 knnMatch k=2 (and
#    knnMatch + the reverse match() a mutual check needs), default threads, medians of 5
#    calls inside each process, processes interleaved. Figure: descriptor pairs (n1 x n2) per
#    second.
# 2. Whole matching stage: identical input for both tools, OpenCV SIFT keypoints and
#    descriptors of the 16 temple photos written as a fresco workspace (match_reference.py
#    prepare, Middlebury K as calibration priors). fresco: `fresco match <ws>` (ratio 0.8,
#    mutual, E/F/H RANSAC, 4 px). OpenCV: knnMatch + mutual check, findEssentialMat (RANSAC
#    0.999, 4 px) + recoverPose. Interleaved, medians of RUNS, wall and CPU seconds; fresco's
#    pair classification is printed.
# Usage: bench/match.sh [runs]   (default 5)     QUICK=1 bench/match.sh  (2 runs, < 4 minutes)
#        NO_BUILD=1 ...  (binaries already in target/release)
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-$(bench/venv.sh opencv)}
QUICK=${QUICK:-0}
RUNS=${1:-$([ "$QUICK" = 1 ] && echo 2 || echo 5)}
if [ "${NO_BUILD:-0}" != 1 ]; then
  cargo build --release -p fresco >&2
  cargo build --release -p fresco-sfm --example match_throughput >&2
fi
TARGET=${CARGO_TARGET_DIR:-target}
FRESCO=$TARGET/release/fresco
THROUGHPUT=$TARGET/release/examples/match_throughput
median() { sort -g | awk '{a[NR]=$1} END {print (NR%2 ? a[(NR+1)/2] : (a[NR/2]+a[NR/2+1])/2)}'; }
field() { "$PYTHON" -c "import json,sys; d=json.loads(sys.stdin.read()); print(d['$1'])"; }
CV=$("$PYTHON" -c 'import cv2; print(cv2.__version__)')

WS=$(mktemp -d)
trap 'rm -rf "$WS"' EXIT

echo "Descriptor matching throughput (median of 5 calls per process, $RUNS processes each, interleaved)"
echo
echo "| pair | n1 x n2 | fresco matches | fresco s | fresco pairs/s | OpenCV knnMatch s | OpenCV knnMatch pairs/s | OpenCV knn + reverse s | fresco speed-up vs knnMatch | fresco pairs/s per kernel (last process) |"
echo "|---|---|---|---|---|---|---|---|---|---|"
for spec in "sceaux 100_7100/100_7101 (8192 max):datasets/sceaux_castle/images/100_7100.JPG:datasets/sceaux_castle/images/100_7101.JPG:8192" \
            "temple 0001/0002 (all):datasets/templeSparseRing/templeSR0001.png:datasets/templeSparseRing/templeSR0002.png:0"; do
  IFS=: read -r label a b nf <<< "$spec"
  "$PYTHON" bench/match_reference.py pair "$WS/pair" "$a" "$b" "$nf" > /dev/null
  : > "$WS/f"; : > "$WS/o"; : > "$WS/o2"
  for r in $(seq "$RUNS"); do
    "$THROUGHPUT" "$WS/pair/a.sift" "$WS/pair/b.sift" 5 > "$WS/f.json"
    field seconds < "$WS/f.json" >> "$WS/f"
    "$PYTHON" bench/match_reference.py throughput "$WS/pair" 5 > "$WS/o.json"
    field knn_seconds < "$WS/o.json" >> "$WS/o"
    field mutual_seconds < "$WS/o.json" >> "$WS/o2"
  done
  fs=$(median < "$WS/f"); os=$(median < "$WS/o"); os2=$(median < "$WS/o2")
  n1=$(field n1 < "$WS/f.json"); n2=$(field n2 < "$WS/f.json")
  kernels=$("$PYTHON" -c "import json,sys; d=json.load(sys.stdin); print(', '.join(f'{k} {v[\"pairs_per_second\"]:.3g}' for k, v in d['kernels'].items()))" < "$WS/f.json")
  printf "| %s | %s x %s | %s | %.4f | %.3g | %.4f | %.3g | %.4f | %.1fx | %s |\n" "$label" "$n1" "$n2" \
    "$(field matches < "$WS/f.json")" "$fs" "$(echo "$n1 * $n2 / $fs" | bc -l)" "$os" \
    "$(echo "$n1 * $n2 / $os" | bc -l)" "$os2" "$(echo "$os / $fs" | bc -l)" "$kernels"
done
echo

"$PYTHON" bench/match_reference.py prepare "$WS/ws" > /dev/null
ow=(); oc=(); fw=(); fc=()
for r in $(seq "$RUNS"); do
    line=$("$PYTHON" bench/match_reference.py opencv "$WS/ws")
    echo "opencv run $r: $line" >&2
    ow+=("$(echo "$line" | sed 's/.*"seconds": \([0-9.e-]*\).*/\1/')")
    oc+=("$(echo "$line" | sed 's/.*"cpu_seconds": \([0-9.e-]*\).*/\1/')")
    /usr/bin/time -f "%e %U %S" -o "$WS/time" $FRESCO --json --quiet match "$WS/ws" > "$WS/summary.json"
    read -r wall user sys < "$WS/time"
    cpu=$(echo "$user + $sys" | bc)
    echo "fresco run $r: wall $wall cpu $cpu verified $(grep -o '"pairs_verified": [0-9]*' "$WS/summary.json")" >&2
    fw+=("$wall"); fc+=("$cpu")
done
mow=$(printf '%s\n' "${ow[@]}" | median); moc=$(printf '%s\n' "${oc[@]}" | median)
mfw=$(printf '%s\n' "${fw[@]}" | median); mfc=$(printf '%s\n' "${fc[@]}" | median)
echo "Matching + verification of 120 temple pairs (median of $RUNS, interleaved)"
echo
echo "| tool | median wall s | median CPU s |"
echo "|---|---|---|"
echo "| OpenCV $CV BFMatcher + findEssentialMat | $mow | $moc |"
echo "| fresco match | $mfw | $mfc |"
echo "| fresco / OpenCV | $(echo "scale=2; $mfw / $mow" | bc) | $(echo "scale=2; $mfc / $moc" | bc) |"
echo
echo "fresco pairs by kind (last run): $("$PYTHON" -c "import json,sys; d=json.load(open(sys.argv[1])); print(json.dumps(d['pairs_by_kind'], sort_keys=True))" "$WS/summary.json")"
echo
echo "load average: $(cut -d' ' -f1-3 /proc/loadavg), $(date -u '+%Y-%m-%d %H:%M UTC'), threads: $(nproc), runs: $RUNS, QUICK=$QUICK"
