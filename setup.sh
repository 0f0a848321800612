#!/usr/bin/env bash
# mocapd setup: installs what is missing (Debian packages only), builds, and runs.
#
#   ./setup.sh run    install, build, start mocapd on its default config fed by a
#                     simulated walking subject, and print live poses
#   ./setup.sh test   install, build, and run the whole test suite (CI calls this)
#   ./setup.sh deps   only install missing Debian packages
#   ./setup.sh build  only configure and build (build/)
#
# Needs root (or sudo) only when packages are missing.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
BUILD="${MOCAP_BUILD_DIR:-$ROOT/build}"
JOBS="${MOCAP_JOBS:-$(nproc)}"

# Everything the build, the tests and the firmware cross-build need.
PACKAGES=(
  build-essential cmake pkg-config git python3
  libeigen3-dev libboost-dev libspdlog-dev libprotobuf-dev protobuf-compiler
  libgtest-dev libgmock-dev libbenchmark-dev libtomlplusplus-dev libcli11-dev libsystemd-dev
  gcc-arm-none-eabi libnewlib-arm-none-eabi binutils-arm-none-eabi gcc-multilib
  clang-14 libclang-rt-14-dev clang-tidy-14 cppcheck
  assimp-utils qemu-system-x86 busybox-static cpio kmod
  blender nodejs
  python3-protobuf python3-numpy python3-matplotlib python3-pytest
  chromium
)

log() { printf '\033[1m[setup]\033[0m %s\n' "$*" >&2; }

deps() {
  npm_deps
  local missing=()
  for p in "${PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed' || missing+=("$p")
  done
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
# the viewer test (it drives Debian's chromium and never downloads a browser).
npm_deps() {
  if ! command -v npm >/dev/null; then return; fi
  local pair dir
  for pair in tests/integration/bvh_consumers:three clients/viewer:three tests/integration/viewer:playwright-core; do
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
  (cd "$BUILD" && ctest --output-on-failure -j "$JOBS" --timeout 900)
}

cmd="${1:-}"
case "$cmd" in
  deps) deps ;;
  build) deps; build ;;
  run) deps; build; run ;;
  test) deps; build; test_all ;;
  *) sed -n '2,12p' "$0" | sed 's/^# \{0,1\}//'; exit 2 ;;
esac
