#!/usr/bin/env bash
# Issue 16 benchmarks (texture sprites, paper 001) on the 2-core machine: the paper's
# figure-1 cases on the synthetic blob (datasets/sprites/*.json): memory beside the paper's
# table 2, lookups per second in surface (baking) order and in random order beside its
# 13-38M lookups/s on a GeForce 6800 GT (table 1: 800x600 x FPS), the depth-9 octree texture
# (bytes per stored texel), the baked GLB's PSNR against the direct rendering, tree
# mip-mapping in the render (distant views with and without the cell means against a 16x16
# supersampled reference: examples/tree_mip_view), and the pictures in
# bench/pictures/sprites_*.png. There is no reference tool: the anchors are the
# paper's own tables.
#
# Usage: bench/sprites.sh          (QUICK=1: fewer lookups per pass; CASES=gears,...: only those
#        sprite cases, no octree/bake). Lookup profile on one thread, the paths before/after the
#        lookup layout in turn: target/release/examples/figure1 --profile surface|random [PASSES]
set -euo pipefail
cd "$(dirname "$0")/.."
echo "start $(date -u +%FT%TZ), load $(cut -d' ' -f1-3 /proc/loadavg)"
cargo build --release -p fresco-sprites --example figure1 --example tree_mip_view
ARGS=()
[[ -n ${QUICK:-} ]] && ARGS+=(--quick)
nice -n 0 target/release/examples/figure1 "${ARGS[@]}"
TM=(--picture bench/pictures/sprites_tree_mip.png)
[[ -n ${CASES:-} ]] && TM+=(--cases "$CASES")
nice -n 0 target/release/examples/tree_mip_view "${TM[@]}"
echo "end $(date -u +%FT%TZ), load $(cut -d' ' -f1-3 /proc/loadavg)"
