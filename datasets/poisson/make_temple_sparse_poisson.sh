#!/usr/bin/env bash
# Regenerates temple_sparse_poisson.ply, the "Poisson mesh of templeSparseRing" that param's
# tests and bench/param.sh unwrap. Dense stereo does not exist in fresco yet, so the mesh is
# made from what exists: `fresco reconstruct` on the 16 photos (SIFT, matching, incremental
# SfM: 16/16 registered, 1,967 sparse points, at main 36ef7c8), then `fresco mesh` on those
# sparse points (normals by PCA + MST orientation, screened Poisson depth 8, density trim 4,
# clean-up, decimation to 25,000 faces). The cloud is thin, so the mesh is a rough open
# shell around the temple's points (one component, Euler characteristic -5: holes and
# handles), not a faithful temple.
#
#   FRESCO=target/release/fresco datasets/poisson/make_temple_sparse_poisson.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
FRESCO=${FRESCO:-target/debug/fresco}
WS=${WS:-bench/out/temple_sparse_ws}
rm -rf "$WS"
mkdir -p "$WS"
"$FRESCO" --threads 1 --quiet reconstruct datasets/templeSparseRing -o "$WS"
"$FRESCO" --quiet mesh "$WS" --points "$WS/sparse/points.ply" --depth 8 --trim 4 --faces 25000
cp "$WS/mesh.ply" datasets/poisson/temple_sparse_poisson.ply
