#!/usr/bin/env bash
# Issue 18, session 4: templeSparseRing without calibration (the focal length from F is tried;
# on this ring it gives no estimate and the default prior stays) and with the Middlebury K
# (as bench/temple_known_k.sh, fresco only), for one or more fresco binaries, interleaved:
# registered images, pose errors against templeSR_par.txt, mean reprojection, the focal
# priors' sources, and CPU seconds of `fresco reconstruct`.
# Usage: bench/sfm_focal.sh [fresco binary ...]   (default target/release/fresco)
#   RUNS=3 bench/sfm_focal.sh /tmp/main-fresco target/release/fresco
set -euo pipefail
cd "$(dirname "$0")/.."
RUNS=${RUNS:-1}
BINS=("$@")
if [ ${#BINS[@]} -eq 0 ]; then BINS=(target/release/fresco); fi
PAR=datasets/templeSparseRing/templeSR_par.txt
OUT=$(mktemp -d /tmp/sfm-focal-XXXX)
printf "1520.4 0 302.32\n0 1525.9 246.87\n0 0 1\n" > "$OUT/K.txt"
echo "start: $(date -u '+%Y-%m-%d %H:%M UTC'), load average: $(cut -d' ' -f1-3 /proc/loadavg), runs: $RUNS"
for r in $(seq "$RUNS"); do
    for bin in "${BINS[@]}"; do
        for mode in no_calibration known_k; do
            ws="$OUT/ws"
            rm -rf "$ws"
            args=()
            if [ $mode = known_k ]; then
                args=(--focal-file "$OUT/K.txt" --camera-model PINHOLE --single-camera)
            fi
            /usr/bin/time -f "%e %U %S" -o "$OUT/time" \
                "$bin" -q --json reconstruct datasets/templeSparseRing "${args[@]}" -o "$ws" > "$OUT/summary.json"
            read -r wall user sys < "$OUT/time"
            sources=$(grep -o '"source": *"[^"]*"' "$OUT/summary.json" | sort | uniq -c | tr -s ' ' | tr '\n' ' ' || true)
            poses=$("$bin" --json eval poses "$ws" --gt "$PAR" | tr -d '\n ' |
                grep -oE '"(registered|median_rotation_deg|max_rotation_deg|median_centre_frac|mean_reprojection_px)":[0-9.e-]+' | tr '\n' ' ')
            echo "$bin $mode run $r: wall $wall cpu $(echo "$user + $sys" | bc) $poses $sources"
        done
    done
done
rm -rf "$OUT"
