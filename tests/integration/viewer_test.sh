#!/usr/bin/env bash
# The live viewer end to end: mocapd (generated config, free ports) fed by mocap-sim
# stream, the page opened in Debian's headless chromium by viewer/viewer_test.mjs
# (playwright-core from npm: `npm ci` in tests/integration/viewer, done by setup.sh).
# With --takes it runs viewer/takes_test.mjs (the Takes panel) instead.
# Usage: viewer_test.sh [--takes] MOCAPD MOCAP_SIM [SAVE_PNG]   (SAVE_PNG: e.g. docs/viewer.png)
set -euo pipefail
takes=0
if [[ "${1:-}" == "--takes" ]]; then takes=1; shift; fi
mocapd="$1"
sim="$2"
save="${3:-}"
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
work="$(mktemp -d)"
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT

if [[ ! -d "$here/viewer/node_modules/playwright-core" ]]; then
  echo "playwright-core missing: run 'npm ci' in $here/viewer (./setup.sh deps)" >&2
  exit 1
fi
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
sink_port=$(free_port); pose_port=$(free_port); http_port=$(free_port)
cat >"$work/mocapd.toml" <<TOML
[log]
stats_interval_s = 0
[ingest]
sink_listen = "127.0.0.1:$sink_port"
[pipeline]
max_subjects = 2
[skeleton]
calibration_dir = "$work"
[serve]
pose_listen = "127.0.0.1:$pose_port"
[outputs]
bvh_live = false
record_dir = "$work"
[control]
token = "viewer-test-token"
[http]
listen = "127.0.0.1:$http_port"
TOML
(cd "$work" && exec "$mocapd" --config "$work/mocapd.toml") >"$work/mocapd.log" 2>&1 &
pids+=($!)
for _ in $(seq 1 100); do
  (exec 3<>"/dev/tcp/127.0.0.1/$http_port") 2>/dev/null && break
  sleep 0.1
done
"$sim" stream --connect "127.0.0.1:$sink_port" --subjects 1 --nodes 15 --rate 100 --motion walk \
  --duration 120 --calibrate-s 6 >"$work/sim.log" 2>&1 &
pids+=($!)
if ((takes)); then
  run=(node "$here/viewer/takes_test.mjs" "http://127.0.0.1:$http_port/?subject=1" viewer-test-token)
else
  run=(node "$here/viewer/viewer_test.mjs" "http://127.0.0.1:$http_port/?subject=1" viewer-test-token "$work" $save)
fi
if ! "${run[@]}"; then
  echo "--- mocapd log ---" >&2
  cat "$work/mocapd.log" >&2
  exit 1
fi
