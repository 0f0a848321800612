#!/usr/bin/env bash
# run_fuzzers.sh [BUILD_DIR] — builds the libFuzzer targets with clang-14 (fuzzer + ASan +
# UBSan, only the sources each target needs) and runs each one for a bounded time from its
# committed seed corpus.
#
#   MOCAP_FUZZ_SECONDS   seconds per target (default 60; 5 is a quick local check)
#   MOCAP_FUZZ_TARGETS   space-separated subset (default: all five)
#   MOCAP_FUZZ_JOBS      build parallelism (default 2)
#
# New interesting inputs go to BUILD_DIR/corpus/<target>, never into the repository; a
# crash leaves BUILD_DIR/artifacts/<target>/crash-* (or leak-/oom-/timeout-), which must be
# copied to tests/fuzz/regressions/<target>/ once fixed so fuzz_replay_tests replays it.
# Prints one summary line per target; exits 1 if any target found something.
set -euo pipefail

here="$(cd "$(dirname "$0")" && pwd)"
build="${1:-$here/../../build-fuzz-clang}"
seconds="${MOCAP_FUZZ_SECONDS:-60}"
targets="${MOCAP_FUZZ_TARGETS:-wire_stream reassembler client_session config bvh}"
jobs="${MOCAP_FUZZ_JOBS:-2}"

declare -A max_len=([wire_stream]=8192 [reassembler]=4096 [client_session]=8192
                    [config]=8192 [bvh]=16384)

start=$(date +%s)
if [[ ! -f "$build/CMakeCache.txt" ]]; then
    CC=clang-14 CXX=clang++-14 cmake -S "$here" -B "$build" -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
fi
cmake --build "$build" -j"$jobs" --target $(printf 'fuzz_%s ' $targets) >/dev/null
echo "fuzz build: $(( $(date +%s) - start )) s"

status=0
printf '%-15s %8s %10s %9s %7s %s\n' target seconds execs exec/s corpus result
for t in $targets; do
    work="$build/corpus/$t"
    artifacts="$build/artifacts/$t"
    log="$build/logs/$t.log"
    mkdir -p "$work" "$artifacts" "$(dirname "$log")"
    rc=0
    # Memory is bounded: no single allocation above 64 MB, 1 GB RSS in all (ASan included).
    "$build/fuzz_$t" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=1024 \
        -malloc_limit_mb=64 -max_len="${max_len[$t]}" -print_final_stats=1 \
        -artifact_prefix="$artifacts/" "$work" "$here/corpus/$t" >"$log" 2>&1 || rc=$?
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
    rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)
    corpus=$(find "$work" "$here/corpus/$t" -type f | wc -l)
    if [[ $rc -eq 0 ]]; then
        result=ok
    else
        result="FOUND (rc=$rc): $(ls "$artifacts" | tr '\n' ' ') see $log"
        status=1
    fi
    printf '%-15s %8s %10s %9s %7s %s\n' "$t" "$seconds" "${execs:-?}" "${rate:-?}" "$corpus" "$result"
done
echo "total: $(( $(date +%s) - start )) s"
exit $status
