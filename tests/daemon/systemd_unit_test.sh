#!/usr/bin/env bash
# Verifies the configured unit (build/systemd/mocapd.service) with systemd's own tools:
# `systemd-analyze verify` (syntax, directives, ExecStart binary exists) and the offline
# security score, which must stay in systemd's "OK" band (< 3.0). verify also runs `man` on
# the unit's Documentation= pages: MAN_DIR holds the generated ones (packaging/CMakeLists.txt).
# Usage: systemd_unit_test.sh UNIT INSTALLED_MOCAPD MOCAPD_BINARY MAN_DIR
set -euo pipefail
unit="$1"
installed="$2"
binary="$3"
export MANPATH="$4"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
# Point ExecStart at the freshly built binary: verify checks that it exists.
grep -q "^ExecStart=${installed} " "$unit"
sed "s#^ExecStart=${installed} #ExecStart=${binary} #" "$unit" > "$tmp/mocapd.service"
systemd-analyze verify "$tmp/mocapd.service"
out="$(systemd-analyze security --offline=true "$tmp/mocapd.service" 2>&1)"
score="$(printf '%s\n' "$out" | sed -n 's/.*Overall exposure level for mocapd.service: \([0-9.]*\).*/\1/p')"
echo "systemd-analyze security score: ${score}"
[[ -n "$score" ]] || { printf '%s\n' "$out"; exit 1; }
awk -v s="$score" 'BEGIN { exit !(s < 3.0) }'
grep -q '^Type=notify' "$unit"
grep -q '^WatchdogSec=' "$unit"
grep -q '^User=mocapd' "$unit"
