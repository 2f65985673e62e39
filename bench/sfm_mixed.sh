#!/usr/bin/env bash
# Issue 18, "one model for a ring": templeSparseRing with every second photo down-scaled to
# 480x360 (the image crate's bilinear filter, as cli/tests/run_bad_input.rs does; a set from
# two cameras). Before the merge through connecting matches the mapper split it into models of
# 12 + 4 images (the top of the ring is weakly tied). Runs features (4096 per photo, as the
# draft preset), exhaustive matching, then sfm twice: with the models merged through the
# verified pairs that connect them (the default) and without (--no-merge-through-matches);
# prints the models' sizes, the mean reprojection error and the poses against the
# Middlebury ground truth (`fresco eval poses`).
# Usage: bench/sfm_mixed.sh        NO_BUILD=1 bench/sfm_mixed.sh
set -euo pipefail
cd "$(dirname "$0")/.."
if [ "${NO_BUILD:-0}" != 1 ]; then
    cargo build --release -p fresco
    cargo build --release -p fresco-sfm --example mixed_size_photos
fi
FRESCO=target/release/fresco
GT=datasets/templeSparseRing/templeSR_par.txt
tmp=$(mktemp -d /tmp/sfm-mixed-XXXXXX)
trap 'rm -rf "$tmp"' EXIT
echo "start: $(date -u '+%Y-%m-%d %H:%M UTC'), load average: $(cut -d' ' -f1-3 /proc/loadavg), cores: $(nproc)"
target/release/examples/mixed_size_photos datasets/templeSparseRing "$tmp/photos"
"$FRESCO" -q features "$tmp/photos" -o "$tmp/ws" --max-features 4096 > /dev/null
"$FRESCO" -q match "$tmp/ws" > /dev/null
for mode in merged split; do
    ws="$tmp/ws_$mode"
    cp -r "$tmp/ws" "$ws"
    flag=()
    if [ $mode = split ]; then flag=(--no-merge-through-matches); fi
    /usr/bin/time -f "%e %U %S" -o "$tmp/time" "$FRESCO" -q --json sfm "$ws" "${flag[@]}" > "$tmp/sfm.json"
    read -r wall user sys < "$tmp/time"
    echo "## $mode: sfm wall $wall s, $(echo "$user + $sys" | bc) CPU-s"
    python3 -c 'import json,sys; s=json.load(open(sys.argv[1])); print("models (images):", [m["images"] for m in s["models"]], " registered:", s["registered"], " mean reprojection px: %.3f" % s["mean_reprojection_px"], " focal px:", s["focal_px"])' "$tmp/sfm.json"
    "$FRESCO" --json eval poses "$ws" --gt "$GT" \
        | grep -E '"(registered|median_rotation_deg|max_rotation_deg|median_centre_frac|max_centre_frac|mean_reprojection_px|median_focal_error)"' || true
    rm -rf "$ws"
done
