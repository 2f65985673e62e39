#!/usr/bin/env bash
# Issue 15: `fresco run` end to end (release build): wall time of each stage, peak memory and
# the held-out PSNR, on templeSparseRing with two photos held out, at each preset named.
#   bench/run.sh                         draft and normal on templeSparseRing
#   QUALITIES="draft" bench/run.sh
#   SET=datasets/sceaux_castle HOLDOUT=a.jpg,b.jpg bench/run.sh
#   NO_BUILD=1 KEEP=1 bench/run.sh       (workspaces kept under /tmp/run-bench.*)
# The machine is shared: the load average is printed before and after each run.
set -euo pipefail
cd "$(dirname "$0")/.."
if [[ -z "${NO_BUILD:-}" ]]; then
    cargo build --release -p fresco
fi
FRESCO=target/release/fresco
SET=${SET:-datasets/templeSparseRing}
HOLDOUT=${HOLDOUT:-templeSR0005.png,templeSR0013.png}
QUALITIES=${QUALITIES:-"draft normal"}
WORK=$(mktemp -d /tmp/run-bench.XXXXXX)
[[ -n "${KEEP:-}" ]] || trap 'rm -rf "$WORK"' EXIT
for q in $QUALITIES; do
    ws=$WORK/$q
    echo "== $SET --quality $q --holdout $HOLDOUT; start $(date -u +%H:%M:%S) UTC, load $(cut -d' ' -f1-3 /proc/loadavg)"
    /usr/bin/time -f "wall %e s, user %U s, system %S s, max RSS %M kB" \
        "$FRESCO" --quiet run "$SET" -o "$ws" --quality "$q" --holdout "$HOLDOUT" >/dev/null
    echo "   end $(date -u +%H:%M:%S) UTC, load $(cut -d' ' -f1-3 /proc/loadavg)"
    python3 - "$ws/summary.json" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
for st in s["stages"]:
    mb = (st["peak_memory_bytes"] or 0) / 1e6
    print(f"   {st['name']:10} {st['status']:8} {st['seconds']:8.1f} s {mb:7.0f} MB")
print(f"   total {s['seconds_total']:.1f} s")
h = s.get("held_out_comparison") or {}
for v in h.get("views", []):
    print(f"   held out {v['name']}: PSNR {v['psnr']:.2f} dB, gain-fitted {v['psnr_gain_fitted']:.2f} dB, "
          f"SSIM {v['ssim_gain_fitted']:.3f}, flat colour {v['psnr_flat_colour']:.2f} dB, {v['pixels']} px")
if h:
    print(f"   mean: PSNR {h['mean_psnr']:.2f} dB, gain-fitted {h['mean_psnr_gain_fitted']:.2f} dB")
PY
done
