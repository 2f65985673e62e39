#!/usr/bin/env bash
# Fuzzing campaign over fresco's file readers (issue 19): builds the cargo-fuzz targets of
# fuzz/ with the nightly toolchain, then runs them one after the other (one core per
# campaign; start a second campaign on other targets to use both), each until it has
# executed RUNS inputs or spent SECONDS, whichever
# comes first, under libFuzzer's 512 MB RSS limit and a 10 s per-input timeout. Prints one
# row per target: executions, time, executions per second, final coverage (edges and
# features), corpus size, crashes (crash/oom/timeout artifacts) and the machine load.
#
#   bench/fuzz.sh                         # every target, 10M executions or 30 minutes each
#   bench/fuzz.sh --seconds 60 ply_bytes  # one target for a minute
#   bench/fuzz.sh --runs 100000           # a quick pass over every target
#   NO_BUILD=1 bench/fuzz.sh obj           # run the targets as last built
#   bench/fuzz.sh --nice 0 obj photo       # full priority (default nice 19: the machine is shared)
#
# Needs: rustup's nightly toolchain and cargo-fuzz (`cargo install cargo-fuzz`).
# Corpora grow in fuzz/corpus/<target> (git-ignored) from the committed seeds in
# fuzz/seeds/<target>; crashing inputs go to fuzz/artifacts/<target>/. Each run's table is
# also written to bench/out/fuzz/<date>.md.
set -euo pipefail
cd "$(dirname "$0")/.."

RUNS=10000000
SECONDS_PER_TARGET=1800
RSS_MB=512
TIMEOUT=10
NICE=19
targets=()
while [[ $# -gt 0 ]]; do
    case "$1" in
        --runs) RUNS="$2"; shift 2 ;;
        --seconds) SECONDS_PER_TARGET="$2"; shift 2 ;;
        --rss-mb) RSS_MB="$2"; shift 2 ;;
        --nice) NICE="$2"; shift 2 ;;
        -h|--help) sed -n '2,21p' "$0"; exit 0 ;;
        *) targets+=("$1"); shift ;;
    esac
done

cd fuzz
if [[ ${#targets[@]} -eq 0 ]]; then
    mapfile -t targets < <(cargo +nightly fuzz list)
fi

echo "building ${#targets[@]} fuzz targets (nightly, release with debug assertions, no sanitizer)" >&2
if [[ -z "${NO_BUILD:-}" ]]; then
    nice -n 19 cargo +nightly fuzz build -O -s none >&2
fi
bin_dir=target/x86_64-unknown-linux-gnu/release

mkdir -p ../bench/out/fuzz
# The process id keeps two campaigns started in the same minute apart.
report=../bench/out/fuzz/$(date +%Y-%m-%d_%H%M)-$$.md
{
    echo "| target | executions | seconds | exec/s | cov | ft | corpus | crashes | load (1 min) |"
    echo "|---|---:|---:|---:|---:|---:|---:|---:|---|"
} | tee "$report"

for t in "${targets[@]}"; do
    corpus=corpus/$t
    artifacts=artifacts/$t
    mkdir -p "$corpus" "$artifacts" "seeds/$t"
    dict=()
    [[ -f dict/$t.dict ]] && dict=(-dict="dict/$t.dict")
    log=$(mktemp)
    load=$(cut -d' ' -f1 /proc/loadavg)
    before=$(find "$artifacts" -type f -name '[cot]*-*' | wc -l)
    started=$(date +%s)
    set +e
    nice -n "$NICE" "$bin_dir/$t" "$corpus" "seeds/$t" "${dict[@]}" \
        -runs="$RUNS" -max_total_time="$SECONDS_PER_TARGET" \
        -rss_limit_mb="$RSS_MB" -malloc_limit_mb="$RSS_MB" -timeout="$TIMEOUT" \
        -print_final_stats=1 -artifact_prefix="$artifacts/" >"$log" 2>&1
    status=$?
    set -e
    load="$load-$(cut -d' ' -f1 /proc/loadavg)"
    last=$(grep -E '^#[0-9]+' "$log" | tail -1 || true)
    execs=$(grep -o 'stat::number_of_executed_units: [0-9]*' "$log" | tail -1 | grep -o '[0-9]*$' || true)
    [[ -z "$execs" ]] && execs=$(echo "$last" | grep -o '^#[0-9]*' | tr -d '#' || true)
    secs=$(grep -o 'Done [0-9]* runs in [0-9]* second' "$log" | tail -1 | awk '{print $5}' || true)
    [[ -z "$secs" ]] && secs=$(( $(date +%s) - started ))
    cov=$(echo "$last" | grep -o 'cov: [0-9]*' | grep -o '[0-9]*' || echo ?)
    ft=$(echo "$last" | grep -o 'ft: [0-9]*' | grep -o '[0-9]*' || echo ?)
    corp=$(echo "$last" | grep -o 'corp: [0-9]*' | grep -o '[0-9]*' || echo ?)
    rate=?
    [[ "$execs" =~ ^[0-9]+$ && "$secs" -gt 0 ]] && rate=$((execs / secs))
    crashes=$(( $(find "$artifacts" -type f -name '[cot]*-*' | wc -l) - before ))
    echo "| $t | $execs | $secs | $rate | $cov | $ft | $corp | $crashes | $load |" | tee -a "$report"
    if [[ $status -ne 0 || $crashes -gt 0 ]]; then
        echo "  $t: libFuzzer exited $status; log tail:" >&2
        grep -E 'ERROR|panicked|SUMMARY|Test unit written' "$log" | head -5 >&2 || true
        cp "$log" "$artifacts/last_failure.log"
    fi
    rm -f "$log"
done
echo "table written to bench/out/fuzz/$(basename "$report")" >&2
