#!/usr/bin/env bash
# Issue 13 figures: the dense stage on the synthetic temple (accuracy / completeness against
# the generator's mesh, default and draft settings) and on templeSparseRing with the
# Middlebury cameras (fraction of fused points inside the published bounding box, time,
# peak memory, the Poisson mesh of the fused cloud). Release build, nice'd.
#
#   bench/dense.sh [quick]     (quick: draft settings only)
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-/tmp/dense-bench}
mkdir -p "$OUT"
cargo build --release -p fresco -p fresco-surface --bins --example dense_synth
FRESCO=target/release/fresco
SYNTH=target/release/examples/dense_synth
uptime
DRAFT="max_image_size=320 scales=2 iterations=4 fine_iterations=1 geometric_iterations=1"

# Synthetic temple, 24 views, 640x480, ground-truth cameras.
[ -d "$OUT/temple" ] || "$FRESCO" --quiet synth temple -o "$OUT/temple"
echo "== synthetic temple, draft"
/usr/bin/time -f "wall %e s, peak RSS %M kB" nice -n 19 "$SYNTH" "$OUT/temple" "$OUT/temple_draft" $DRAFT | grep -v "valid"
# Support plane: the same object on a textured floor (with walls); the floor is removed.
[ -d "$OUT/backdrop" ] || "$FRESCO" --quiet synth temple --views 16 --backdrop -o "$OUT/backdrop"
echo "== synthetic temple on a floor (--backdrop), 16 views, draft"
/usr/bin/time -f "wall %e s, user %U s, peak RSS %M kB" nice -n 19 "$SYNTH" "$OUT/backdrop" "$OUT/backdrop_draft" $DRAFT | grep -v "valid"
if [ "${1:-}" != quick ]; then
  echo "== synthetic temple, default"
  /usr/bin/time -f "wall %e s, peak RSS %M kB" nice -n 19 "$SYNTH" "$OUT/temple" "$OUT/temple_default" | grep -v "valid"
  [ -d "$OUT/weak" ] || "$FRESCO" --quiet synth temple --albedo-contrast 0.1 -o "$OUT/weak"
  echo "== weakly textured synthetic temple (albedo contrast 0.1), default"
  /usr/bin/time -f "wall %e s, peak RSS %M kB" nice -n 19 "$SYNTH" "$OUT/weak" "$OUT/weak_default" | grep -v "valid"
fi

# templeSparseRing with the Middlebury cameras (COLMAP's sparse points, moved onto them).
BOX="-0.073568 0.021728 -0.012445 0.028855 0.181892 0.062736"
for preset in draft default; do
  [ "$preset" = default ] && [ "${1:-}" = quick ] && continue
  flag=""; [ "$preset" = draft ] && flag="--draft"
  echo "== templeSparseRing, Middlebury cameras, $preset"
  /usr/bin/time -f "wall %e s, peak RSS %M kB" nice -n 19 "$FRESCO" --quiet dense $flag \
    --colmap datasets/reference/colmap/templeSparseRing_known_k --images datasets/templeSparseRing \
    --poses datasets/templeSparseRing/templeSR_par.txt -o "$OUT/real_$preset" --json \
    | python3 -c 'import json,sys; s=json.load(sys.stdin); print("points", s["fusion"]["points"], "patch match", round(s["seconds_patch_match"],1), "s, geometric", round(s["seconds_geometric"],1), "s, fusion", round(s["seconds_fusion"],1), "s, total", round(s["seconds_total"],1), "s")'
  python3 bench/dense_bbox.py "$OUT/real_$preset/dense/fused.ply" $BOX
  python3 bench/dense_bbox.py "$OUT/real_$preset/dense/fused.ply" $BOX 0.01
done
