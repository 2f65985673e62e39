#!/usr/bin/env bash
# Issue 4 benchmarks (structure from motion), on this 2-core shared machine:
#  1. bundle adjustment alone: seconds per Levenberg-Marquardt iteration on a synthetic
#     problem of 200 cameras and 50,000 points (tracks of up to 8 views, 0.5 px noise),
#     median of 3 runs of 10 iterations (sfm/examples/ba_bench.rs);
#  2. whole sfm (features, exhaustive matching, mapping with BA) on templeSparseRing and
#     sceaux_castle (1600 px): fresco vs pycolmap on the same images, interleaved
#     (COLMAP, fresco, COLMAP, fresco, ...), median of 3, wall and CPU seconds; fresco runs
#     `fresco reconstruct` and its poses are measured with `fresco eval poses` against the
#     ground truth (temple) or COLMAP's committed model (sceaux).
# Usage: bench/sfm.sh [ba|whole|all]   (default all)
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-/work/venv/bin/python}
WHAT=${1:-all}
RUNS=3

cargo build --release -p fresco-sfm --example ba_bench
cargo build --release -p fresco
FRESCO=target/release/fresco

median() { sort -g | awk '{a[NR]=$1} END {print (NR%2 ? a[(NR+1)/2] : (a[NR/2]+a[NR/2+1])/2)}'; }

if [[ $WHAT == ba || $WHAT == all ]]; then
    echo "## bundle adjustment: 200 cameras, 50k points, 10 LM iterations, threads: $(nproc)"
    per=()
    for r in $(seq $RUNS); do
        line=$(target/release/examples/ba_bench 200 50000 8 10)
        echo "$line"
        per+=("$(echo "$line" | sed 's/.*"seconds_per_iteration":\([0-9.e-]*\).*/\1/')")
    done
    echo "median seconds per LM iteration: $(printf '%s\n' "${per[@]}" | median)"
fi

if [[ $WHAT == whole || $WHAT == all ]]; then
    for set in templeSparseRing sceaux_castle; do
        case $set in
            templeSparseRing) imgs=datasets/templeSparseRing ;;
            sceaux_castle) imgs=datasets/sceaux_castle/images ;;
        esac
        case $set in
            templeSparseRing) gt=datasets/templeSparseRing/templeSR_par.txt ;;
            sceaux_castle) gt=datasets/reference/colmap/sceaux_castle ;;
        esac
        cw=(); cc=(); fw=(); fc=()
        for r in $(seq $RUNS); do
            line=$($PYTHON bench/sfm_colmap.py "$imgs")
            echo "colmap $set run $r: $line"
            cw+=("$(echo "$line" | sed 's/.*"wall": \([0-9.e-]*\).*/\1/')")
            cc+=("$(echo "$line" | sed 's/.*"cpu": \([0-9.e-]*\).*/\1/')")
            ws=$(mktemp -d)
            # The whole pipeline in one command (features, exhaustive matching, mapping + BA).
            /usr/bin/time -f "%e %U %S" -o "$ws.time" \
                "$FRESCO" -q reconstruct "$imgs" -o "$ws" || echo "fresco reconstruct failed on $set"
            read -r wall user sys < "$ws.time"
            # Poses against ground truth (temple) or COLMAP's committed model (sceaux).
            echo "fresco $set run $r: wall $wall cpu $(echo "$user + $sys" | bc)"
            "$FRESCO" --json eval poses "$ws" --gt "$gt" | grep -E '"(registered|median_rotation_deg|median_centre_frac|mean_reprojection_px)"' || true
            fw+=("$wall"); fc+=("$(echo "$user + $sys" | bc)")
            rm -rf "$ws" "$ws.time"
        done
        mcw=$(printf '%s\n' "${cw[@]}" | median); mcc=$(printf '%s\n' "${cc[@]}" | median)
        mfw=$(printf '%s\n' "${fw[@]}" | median); mfc=$(printf '%s\n' "${fc[@]}" | median)
        echo "| $set | COLMAP wall $mcw s cpu $mcc s | fresco wall $mfw s cpu $mfc s | fresco/COLMAP wall $(echo "scale=2; $mfw / $mcw" | bc) |"
    done
fi
