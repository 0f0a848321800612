#!/usr/bin/env bash
# mocapd setup: installs what is missing (Debian packages only), builds, and runs.
#
#   ./setup.sh run    install, build, start mocapd on its default config fed by a
#                     simulated walking subject, and print live poses
#   ./setup.sh test   install, build, and run the whole test suite (CI calls this):
#                     ctest (unit, integration, SocketCAN VM, real BVH consumers, viewer in
#                     chromium, Python client, static analysis), the libFuzzer targets for
#                     a bounded time, the whole suite again under ASan+UBSan, and the
#                     threaded code's tests under ThreadSanitizer; a failed ctest
#                     phase ends with a digest of why each test failed
#                     (tests/ctest_digest.py), so the tail of the log says it
#   ./setup.sh sanitize [tsan|asan|all]   only the sanitizer phases (tests/sanitize.sh,
#                     docs/reliability.md)
#   ./setup.sh deps   only install missing Debian packages
#   ./setup.sh build  only configure and build (build/)
#   ./setup.sh fuzz   only the fuzz phase of the test command
#
# Environment: MOCAP_JOBS (parallelism), MOCAP_FUZZ_SECONDS (per fuzz target, default 30).
# Needs root (or sudo) only when packages are missing.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
BUILD="${MOCAP_BUILD_DIR:-$ROOT/build}"
JOBS="${MOCAP_JOBS:-$(nproc)}"
# ccache (CMakeLists.txt uses it when installed) keys on paths relative to the clone, so two
# clones of the same commit share their cache entries.
export CCACHE_BASEDIR="${CCACHE_BASEDIR:-$ROOT}"

# Everything the build, the tests and the firmware cross-build need.
PACKAGES=(
  build-essential cmake pkg-config git python3 systemd
  help2man lintian debootstrap
  libeigen3-dev libboost-dev libspdlog-dev libprotobuf-dev protobuf-compiler
  libgtest-dev libgmock-dev libbenchmark-dev libtomlplusplus-dev libcli11-dev libsystemd-dev
  nats-server libnats-dev libssl-dev
  liblo-dev liblo-tools python3-liblo
  gcc-arm-none-eabi libnewlib-arm-none-eabi binutils-arm-none-eabi gcc-multilib python3-unicorn
  openocd stlink-tools
  clang-14 libclang-rt-14-dev clang-tidy-14 clang-format-14 cppcheck ccache lld nlohmann-json3-dev
  assimp-utils qemu-system-x86 qemu-user busybox-static cpio kmod
  blender nodejs
  python3-protobuf python3-numpy python3-matplotlib python3-pytest python3-venv python3-setuptools python3-wheel
  chromium
)

log() { printf '\033[1m[setup]\033[0m %s\n' "$*" >&2; }

deps() {
  npm_deps
  local missing=()
  for p in "${PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed' || missing+=("$p")
  done
  # Debian 12 packages npm apart from nodejs. Asked for only when the command is missing: a
  # nodejs from elsewhere (NodeSource) brings its own npm and conflicts with Debian's.
  if ! command -v npm >/dev/null; then missing+=(npm); fi
  if ((${#missing[@]} == 0)); then
    log "all Debian packages present"
    return
  fi
  log "installing: ${missing[*]}"
  local sudo=()
  if [[ $(id -u) -ne 0 ]]; then sudo=(sudo); fi
  "${sudo[@]}" apt-get update -qq
  DEBIAN_FRONTEND=noninteractive "${sudo[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
  npm_deps
}

# npm registry, pinned in each package-lock.json: three.js (BVHLoader) for the BVH consumer
# tests; three.js for the viewer (embedded into mocapd at build time); playwright-core for
# the viewer test (it drives Debian's chromium and never downloads a browser); nats (nats.js)
# as the foreign subscriber of the cluster test.
npm_deps() {
  if ! command -v npm >/dev/null; then return; fi
  local pair dir
  for pair in tests/integration/bvh_consumers:three clients/viewer:three tests/integration/viewer:playwright-core \
      tests/integration/nats_js:nats; do
    dir="$ROOT/${pair%%:*}"
    if [[ -d "$dir/node_modules/${pair##*:}" ]]; then continue; fi
    log "npm: installing ${pair##*:} in ${pair%%:*}"
    (cd "$dir" && npm ci --no-audit --no-fund --silent) || log "npm install failed in ${pair%%:*}: its tests will fail"
  done
}

build() {
  log "configuring $BUILD"
  cmake -S "$ROOT" -B "$BUILD" -DCMAKE_BUILD_TYPE=Release >/dev/null
  log "building with $JOBS jobs"
  cmake --build "$BUILD" -j "$JOBS"
}

run() {
  exec "$ROOT/tests/run_demo.sh" "$BUILD"
}

test_all() {
  (cd "$BUILD" && ctest --output-on-failure -j "$JOBS" --timeout 900 --output-junit ctest-junit.xml) || {
    local rc=$?
    python3 "$ROOT/tests/ctest_digest.py" "$BUILD/ctest-junit.xml"  # the reasons, last: a log's tail shows them
    return "$rc"
  }
}

fuzz() {
  MOCAP_FUZZ_SECONDS="${MOCAP_FUZZ_SECONDS:-30}" MOCAP_FUZZ_JOBS="$JOBS" \
    "$ROOT/tests/fuzz/run_fuzzers.sh" "$ROOT/build-fuzz-clang"
}

sanitize() {
  MOCAP_SANITIZE_JOBS="$JOBS" "$ROOT/tests/sanitize.sh" "${1:-all}"
}

phase() {  # phase NAME FUNCTION...: runs one phase of the test command and times it
  local name="$1" start=$SECONDS
  shift
  log "phase $name"
  "$@"
  log "phase $name: passed in $((SECONDS - start)) s"
}

cmd="${1:-}"
case "$cmd" in
  deps) deps ;;
  build) deps; build ;;
  run) deps; build; run ;;
  test)
    phase deps deps
    phase build build
    phase ctest test_all
    phase fuzz fuzz
    phase asan sanitize asan
    phase tsan sanitize tsan
    ;;
  fuzz) deps; fuzz ;;
  sanitize) deps; sanitize "${2:-all}" ;;
  *) sed -n '2,18p' "$0" | sed 's/^# \{0,1\}//'; exit 2 ;;
esac
