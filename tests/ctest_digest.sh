#!/usr/bin/env bash
# ctest_digest.sh BUILD_DIR — after a failed ctest run, prints a short digest of each failed
# test from BUILD_DIR/Testing/Temporary/LastTest.log: its name, how it ended and the lines
# that say why (gtest failures with the 6 lines after each, pytest "E" lines, sanitizer and
# runtime errors), at most 40 lines per test. The test command's phases print it last, so a
# reader who sees only the tail of a long log (a CI summary) still sees the reason.
set -euo pipefail
log="${1:?usage: ctest_digest.sh BUILD_DIR}/Testing/Temporary/LastTest.log"
[[ -f "$log" ]] || { echo "ctest digest: no $log" >&2; exit 0; }
echo "=== ctest digest: why each failed test failed (whole output above) ==="
awk '
  function flush() {
    if (name != "" && !passed) {
      print "--- " name " (" (ended != "" ? ended : "no result line") ")"
      for (i = 1; i <= n && i <= 40; ++i) print "  " keep[i]
      if (n > 40) print "  ... " (n - 40) " more lines"
    }
    name = ""; passed = 0; ended = ""; n = 0; after = 0
  }
  / Testing: / && $2 == "Testing:" { flush(); name = $3; next }
  name == "" { next }
  /^Test Passed\./ { passed = 1; next }
  /^Test (Failed|Timeout)|^Test .*(aborted|Exception|SEGFAULT|Killed)/ { ended = $0; next }
  after > 0 { keep[++n] = $0; --after; next }
  /Failure$|: Failure|^E   |ERROR: [A-Za-z]*Sanitizer|runtime error:|LeakSanitizer|SUMMARY: |Assertion.*failed|terminate called/ {
    keep[++n] = $0
    if ($0 ~ /Failure$/) after = 6
  }
  END { flush() }
' "$log"
