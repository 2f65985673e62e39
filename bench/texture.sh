#!/usr/bin/env bash
# Issue 14: texture reconstruction on the synthetic scenes (24 views at 640x480, views 5 and
# 17 held out, textured from the other 22 with the ground-truth mesh and cameras): held-out
# PSNR (raw and gain-fitted), SSIM, 1-NCC of fresco's texture and of the per-vertex colour
# baseline, with the texture's timings and peak memory.
#   bench/texture.sh              all scenes (torus, temple, blob at detail 2; torus detail 4)
#   SCENES="temple:2" bench/texture.sh
#   NO_BUILD=1 bench/texture.sh   skip the build
set -euo pipefail
cd "$(dirname "$0")/.."
if [[ -z "${NO_BUILD:-}" ]]; then
    cargo build --release -p fresco-atlas --example heldout
fi
SCENES=${SCENES:-"torus:2 temple:2 blob:2 torus:4"}
echo "start $(date -u +%H:%M:%S) UTC, load: $(cut -d' ' -f1-3 /proc/loadavg)"
for s in $SCENES; do
    shape=${s%%:*}
    detail=${s##*:}
    /usr/bin/time -f "  peak RSS %M kB, wall %e s (dataset rendering included)" \
        target/release/examples/heldout "$shape" "$detail"
done
echo "end $(date -u +%H:%M:%S) UTC, load: $(cut -d' ' -f1-3 /proc/loadavg)"
