#!/usr/bin/env bash
# sanitize.sh [asan|tsan|all] — builds the project with g++ sanitizers and runs the tests.
#
#   asan  -DMOCAP_SANITIZE=address,undefined, whole project; the whole ctest suite except the
#         SocketCAN VM test, the ARM cross-compiles, the firmware images in the emulator and
#         static analysis (they run no instrumented host code of ours beyond a frame decoder)
#         and the descriptor-exhaustion test (see run_asan).
#         The fuzz replay test runs here too, so every seed and regression input is
#         replayed under ASan/UBSan built by g++ as well.
#   tsan  -DMOCAP_SANITIZE=thread; the threaded code's tests: core (rings, worker pool,
#         assembler), ingest (sink listener), serve (pose server, broadcaster, clients, live
#         BVH, HTTP/WebSocket, recorders, the VMC sender) and the integration tests, which run the TSan-built
#         mocapd itself (the wired pipeline: ingest, workers, assembler, servers, recorder
#         writers on a full disk, signals, a played take, takes recorded and exported).
#         ctest -R selects their test suites by name.
#   all   both (default).
#
# Environment: MOCAP_SANITIZE_BUILD_ROOT (default: the repository root) holds build-asan/ and
# build-tsan/; MOCAP_SANITIZE_JOBS (default 2) is the build and ctest parallelism;
# MOCAP_SANITIZE_UNITY=OFF compiles every source on its own (default ON, see configure).
# Prints the time each phase took; exits non-zero if a build or a test failed.
set -euo pipefail

root="$(cd "$(dirname "$0")/.." && pwd)"
what="${1:-all}"
out="${MOCAP_SANITIZE_BUILD_ROOT:-$root}"
jobs="${MOCAP_SANITIZE_JOBS:-2}"
# Fail on the first report; leaks are errors; symbolised stacks.
export ASAN_OPTIONS="${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1}"
export UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}"
export TSAN_OPTIONS="${TSAN_OPTIONS:-halt_on_error=1:second_deadlock_stack=1}"

tsan_executables=(core_tests ingest_tests serve_tests serve_outputs_tests serve_http_tests serve_vmc_tests
                  daemon_integration_tests faults_integration_tests http_integration_tests
                  disk_integration_tests limits_integration_tests play_integration_tests takes_integration_tests)

# ctest in DIR with ARGS; after a failure the digest of why (tests/ctest_digest.py) comes last.
run_ctest() {
    local dir="$1"; shift
    local rc=0
    (cd "$dir" && ctest --output-on-failure -j "$jobs" --timeout 900 --output-junit ctest-junit.xml "$@") || rc=$?
    [[ $rc -eq 0 ]] || python3 "$root/tests/ctest_digest.py" "$dir/ctest-junit.xml"
    return "$rc"
}

status=0
phase() {  # phase NAME COMMAND... — runs, times and reports one step
    local name="$1"; shift
    local rc=0 TIMEFORMAT="sanitize: $name: %0R s wall, %0U s user + %0S s sys CPU (this shell's children)"
    time { "$@" || rc=$?; }
    echo "sanitize: $name: exit $rc"
    [[ $rc -eq 0 ]] || status=1
    return 0
}

# -g1: line tables and function names, which is all a sanitizer report prints; no
# variable info, which makes the sanitizer builds ~25 % faster to compile than -g.
# -O1: compiling is most of a sanitizer phase and running the tests a small part, and -O1
# (what the ASan and TSan documentation suggest) compiles much faster than -O2
# (docs/reliability.md, test command time).
# Unity builds: each target's sources are compiled as batches of up to 8 in one translation
# unit, so Asio, Beast, protobuf, gtest and Eigen are parsed and instantiated once per batch
# instead of once per file (docs/reliability.md, test command time). Only here: the Release
# build's compile_commands.json, which static analysis reads, keeps one entry per real file.
# The sources that cannot share a unit are listed in cmake/unity_exceptions.cmake.
configure() {  # configure DIR SANITIZERS [CMAKE ARGS...]
    local dir="$1" sanitizers="$2"; shift 2
    cmake -S "$root" -B "$dir" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DMOCAP_SANITIZE="$sanitizers" \
        -DCMAKE_C_FLAGS_RELWITHDEBINFO="-O1 -g1 -DNDEBUG" \
        -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1 -DNDEBUG" \
        -DCMAKE_UNITY_BUILD="${MOCAP_SANITIZE_UNITY:-ON}" -DCMAKE_UNITY_BUILD_BATCH_SIZE=8 "$@" >/dev/null
}

# Suite names of the given test executables as one ctest regex: ^(A|B)\.
suite_regex() {
    local dir="$1"; shift
    local suites=()
    for exe in "$@"; do
        local path
        path=$(find "$dir/tests" -type f -name "$exe" -perm -u+x | head -1)
        [[ -n "$path" ]] || { echo "sanitize: $exe not built, its tests are skipped" >&2; continue; }
        # --gtest_list_tests prints "Suite." lines (parameterised: "Prefix/Suite.").
        while read -r s; do suites+=("$s"); done < <("$path" --gtest_list_tests | sed -n 's/^\([^ ].*\)\.\( .*\)\{0,1\}$/\1/p')
    done
    local IFS='|'
    echo "^(${suites[*]})\\."
}

run_asan() {
    local b="$out/build-asan"
    phase "asan configure" configure "$b" address,undefined
    # -k: a target that fails to build does not stop the others (the failure is reported).
    phase "asan build" cmake --build "$b" -j"$jobs" -- -k
    # The descriptor-exhaustion test is left to the plain and TSan runs: g++ links UBSan as a
    # separate runtime that starts on its first check of a new dynamic type and probes object
    # memory through a pipe, so with every descriptor in use (the point of that test) it calls
    # a valid protobuf message a bad one. No UBSan option avoids it (its suppression file is
    # opened at that same moment).
    phase "asan ctest" run_ctest "$b" -E 'socketcan_vm|_arm_|firmware_loop|static_analysis|AcceptBacksOffWhenDescriptorsRunOut'
}

run_tsan() {
    local b="$out/build-tsan"
    # g++ 12 warns (-Wtsan, an error with -Werror) that ThreadSanitizer cannot see
    # std::atomic_thread_fence, which Asio's handler fences use; Asio synchronises through
    # mutexes, which it does see. Every Asio user needs the switch, not only mocap_serve.
    phase "tsan configure" configure "$b" thread -DCMAKE_CXX_FLAGS=-Wno-tsan
    phase "tsan build" cmake --build "$b" -j"$jobs" --target "${tsan_executables[@]}" -- -k
    local regex
    regex=$(suite_regex "$b" "${tsan_executables[@]}") || { status=1; return 0; }
    echo "sanitize: tsan ctest -R '$regex'"
    phase "tsan ctest" run_ctest "$b" -R "$regex"
}

case "$what" in
    asan) run_asan ;;
    tsan) run_tsan ;;
    all) run_asan; run_tsan ;;
    *) echo "usage: $0 [asan|tsan|all]" >&2; exit 2 ;;
esac
exit $status
