#!/usr/bin/env bash
# Issue 4 benchmarks (structure from motion), on this 2-core shared machine:
#  1. bundle adjustment alone: seconds per Levenberg-Marquardt iteration on a synthetic
#     problem of 200 cameras and 50,000 points (tracks of up to 8 views, 0.5 px noise),
#     median of RUNS runs of 10 iterations (sfm/examples/ba_bench.rs);
#  2. whole sfm (features, exhaustive matching, mapping with BA) on templeSparseRing and
#     sceaux_castle (1600 px, both tools at their default 3200 px limit: same image sizes):
#     pycolmap vs `fresco reconstruct`, interleaved (COLMAP, fresco, COLMAP, fresco, ...),
#     median of RUNS, wall and CPU seconds and each tool's phase times; fresco's poses
#     measured with `fresco eval poses` against the ground truth (temple) or COLMAP's
#     committed model (sceaux), and each fresco model read back by COLMAP itself
#     (datasets/reference/read_fresco_model.py: same counts, poses, reprojection error);
#  3. accuracy: the templeSparseRing test (features through BA in one process, both tools'
#     pose errors against the ground truth), sfm/tests/temple_sfm.rs, in the release profile.
# Usage: bench/sfm.sh [ba|whole|accuracy|all]   (default all)
#   QUICK=1 bench/sfm.sh      # one run each
#   NO_BUILD=1 RUNS=5 bench/sfm.sh whole
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-$(bench/venv.sh colmap)}
WHAT=${1:-all}
RUNS=${RUNS:-3}
if [ "${QUICK:-0}" = 1 ]; then RUNS=1; fi

if [ "${NO_BUILD:-0}" != 1 ]; then
    cargo build --release -p fresco-sfm --example ba_bench
    cargo build --release -p fresco
fi
FRESCO=target/release/fresco
echo "start: $(date -u '+%Y-%m-%d %H:%M UTC'), load average: $(cut -d' ' -f1-3 /proc/loadavg), cores: $(nproc), runs: $RUNS"

median() { sort -g | awk '{a[NR]=$1} END {print (NR%2 ? a[(NR+1)/2] : (a[NR/2]+a[NR/2+1])/2)}'; }
field() { sed -n "s/.*\"$1\": *\([0-9.e+-]*\).*/\1/p" | head -1; }

if [[ $WHAT == ba || $WHAT == all ]]; then
    echo "## bundle adjustment: 200 cameras, 50k points, 10 LM iterations"
    per=()
    for r in $(seq "$RUNS"); do
        line=$(target/release/examples/ba_bench 200 50000 8 10)
        echo "$line"
        per+=("$(echo "$line" | sed 's/.*"seconds_per_iteration":\([0-9.e-]*\).*/\1/')")
    done
    echo "median seconds per LM iteration: $(printf '%s\n' "${per[@]}" | median)"
fi

if [[ $WHAT == whole || $WHAT == all ]]; then
    echo "## whole sfm"
    table=()
    for set in templeSparseRing sceaux_castle; do
        case $set in
            templeSparseRing) imgs=datasets/templeSparseRing; gt=datasets/templeSparseRing/templeSR_par.txt ;;
            sceaux_castle) imgs=datasets/sceaux_castle/images; gt=datasets/reference/colmap/sceaux_castle ;;
        esac
        cw=(); cc=(); fw=(); fc=(); cph=(); fph=()
        for r in $(seq "$RUNS"); do
            line=$($PYTHON bench/sfm_colmap.py "$imgs" 2>/dev/null)
            echo "colmap $set run $r: $line"
            cw+=("$(echo "$line" | field wall)"); cc+=("$(echo "$line" | field cpu)")
            cph+=("$(echo "$line" | field extract) $(echo "$line" | field match) $(echo "$line" | field map)")
            ws=$(mktemp -d)
            # The whole pipeline in one command (features, exhaustive matching, mapping + BA).
            /usr/bin/time -f "%e %U %S" -o "$ws.time" \
                "$FRESCO" -q --json reconstruct "$imgs" -o "$ws" > "$ws.json" || echo "fresco reconstruct failed on $set"
            read -r wall user sys < "$ws.time"
            phases=$(tr -d '\n ' < "$ws.json" | sed -n 's/.*"seconds":{"features":\([0-9.]*\),"match":\([0-9.]*\),"sfm":\([0-9.]*\).*/\1 \2 \3/p')
            echo "fresco $set run $r: wall $wall cpu $(echo "$user + $sys" | bc) phases (features match sfm) $phases"
            # COLMAP itself reads the model back and finds what fresco reported.
            "$PYTHON" datasets/reference/read_fresco_model.py "$ws/sparse/0" "$ws.json" \
                2>/dev/null || echo "COLMAP read-back of fresco's $set model FAILED"
            # Poses against ground truth (temple) or COLMAP's committed model (sceaux).
            "$FRESCO" --json eval poses "$ws" --gt "$gt" | grep -E '"(registered|median_rotation_deg|median_centre_frac|mean_reprojection_px)"' || true
            fw+=("$wall"); fc+=("$(echo "$user + $sys" | bc)"); fph+=("$phases")
            rm -rf "$ws" "$ws.time" "$ws.json"
        done
        mcw=$(printf '%s\n' "${cw[@]}" | median); mcc=$(printf '%s\n' "${cc[@]}" | median)
        mfw=$(printf '%s\n' "${fw[@]}" | median); mfc=$(printf '%s\n' "${fc[@]}" | median)
        # Median of column $1 of the phase lines that follow.
        col() { local k=$1; shift; printf '%s\n' "$@" | awk -v k="$k" '{print $k}' | median; }
        ce=$(col 1 "${cph[@]}"); cm=$(col 2 "${cph[@]}"); cmap=$(col 3 "${cph[@]}")
        fe=$(col 1 "${fph[@]}"); fm=$(col 2 "${fph[@]}"); fmap=$(col 3 "${fph[@]}")
        r1() { printf '%.1f' "$1"; }
        table+=("| $set | $(r1 "$mcw") | $(r1 "$mcc") | $(r1 "$ce") / $(r1 "$cm") / $(r1 "$cmap") | $(r1 "$mfw") | $(r1 "$mfc") | $(r1 "$fe") / $(r1 "$fm") / $(r1 "$fmap") | $(printf '%.2f' "$(echo "$mfw / $mcw" | bc -l)") |")
    done
    echo
    echo "| set | COLMAP wall s | COLMAP CPU s | COLMAP extract / match / map s | fresco wall s | fresco CPU s | fresco features / match / sfm s | fresco/COLMAP wall |"
    echo "|---|---|---|---|---|---|---|---|"
    printf '%s\n' "${table[@]}"
fi

if [[ $WHAT == accuracy || $WHAT == all ]]; then
    echo "## templeSparseRing accuracy (sfm/tests/temple_sfm.rs, release profile)"
    cargo test --release -p fresco-sfm --test temple_sfm -- --nocapture 2>&1 \
        | grep -E "^(fresco|COLMAP)|test result|panicked|assert" || true
fi
