#!/usr/bin/env bash
# Self-test of run_static.sh's record of clean units: a unit recorded clean is skipped, and
# a change in a header it includes makes it be analysed again, so a new finding there fails
# the run. Builds a throwaway source tree with one unit and one header, and a copy of the
# analysis set-up (script, .clang-tidy, lists), and runs the script three times.
set -euo pipefail
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
ROOT="$(cd "$HERE/../.." && pwd)"
T="$(mktemp -d)"
trap 'rm -rf "$T"' EXIT
mkdir -p "$T/tree/tests/static" "$T/tree/server" "$T/tree/build"
cp "$HERE/run_static.sh" "$HERE/known.txt" "$HERE/cppcheck.supp" "$T/tree/tests/static/"
cp "$ROOT/.clang-tidy" "$T/tree/"
cat >"$T/tree/server/unit.hpp" <<'H'
#pragma once
inline int half(int x) { return x / 2; }
H
cat >"$T/tree/server/unit.cpp" <<'C'
#include "unit.hpp"
int quarter(int x) { return half(half(x)); }
C
cat >"$T/tree/build/compile_commands.json" <<J
[{"directory": "$T/tree/build", "file": "$T/tree/server/unit.cpp",
  "command": "/usr/bin/c++ -I$T/tree/server -std=c++20 -o unit.o -c $T/tree/server/unit.cpp"}]
J
run() {
  MOCAP_STATIC_TOOLS=clang-tidy MOCAP_STATIC_CACHE="$T/cache" "$T/tree/tests/static/run_static.sh" "$T/tree/build" \
    >"$T/out" 2>&1 || echo "exit $?" >>"$T/out"
  cat "$T/out"
}
fail() { echo "FAIL: $*"; exit 1; }

run | grep -q '0 of 1 units unchanged' || fail "first run did not analyse the unit"
grep -q '^\[static\] clean' "$T/out" || fail "first run not clean"
run | grep -q '1 of 1 units unchanged' || fail "a unit analysed clean was analysed again"
grep -q '^\[static\] clean' "$T/out" || fail "second run not clean"
# A finding in the header (a self-assignment: bugprone/misc redundant-expression family);
# the unit's own text is unchanged.
cat >"$T/tree/server/unit.hpp" <<'H'
#pragma once
inline int half(int x) { return (x / 2) == (x / 2) ? x / 2 : 0; }
H
run | grep -q '0 of 1 units unchanged' || fail "a changed header did not make its unit be analysed again"
grep -q '^exit 1' "$T/out" || fail "the header's finding did not fail the run"
echo "tidy cache self-test: passed"
