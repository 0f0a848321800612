#!/usr/bin/env bash
# Verifies systemd/mocapd.service with systemd's own tools: `systemd-analyze verify`
# (syntax, directives, ExecStart binary exists) and the offline security score, which
# must stay in systemd's "OK" band (< 3.0). Usage: systemd_unit_test.sh UNIT MOCAPD_BINARY
set -euo pipefail
unit="$1"
binary="$2"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
# Point ExecStart at the freshly built binary: verify checks that it exists.
sed "s#/usr/local/bin/mocapd#${binary}#" "$unit" > "$tmp/mocapd.service"
systemd-analyze verify "$tmp/mocapd.service"
out="$(systemd-analyze security --offline=true "$tmp/mocapd.service" 2>&1)"
score="$(printf '%s\n' "$out" | sed -n 's/.*Overall exposure level for mocapd.service: \([0-9.]*\).*/\1/p')"
echo "systemd-analyze security score: ${score}"
[[ -n "$score" ]] || { printf '%s\n' "$out"; exit 1; }
awk -v s="$score" 'BEGIN { exit !(s < 3.0) }'
grep -q '^Type=notify' "$unit"
grep -q '^WatchdogSec=' "$unit"
grep -q '^User=mocapd' "$unit"
