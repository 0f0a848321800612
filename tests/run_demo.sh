#!/usr/bin/env bash
# The README's run command (./setup.sh run): mocapd on its embedded default config, fed by
# one simulated walking subject (mocap-sim stream acting as the sink node), and live poses
# printed by mocap-client. Ctrl-C stops all three.
# Usage: run_demo.sh BUILD_DIR [extra mocap-client cat options]
set -euo pipefail
build="$1"
shift
bin_mocapd="$build/server/daemon/mocapd"
bin_sim="$build/clients/sim/mocap-sim"
bin_client="$build/clients/client/mocap-client"
work="$(mktemp -d)"
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT INT TERM

wait_port() {  # the daemon is ready once its port accepts
  for _ in $(seq 1 100); do
    (exec 3<>"/dev/tcp/127.0.0.1/$1") 2>/dev/null && return 0
    sleep 0.1
  done
  echo "port $1 did not open; see $work/mocapd.log" >&2
  exit 1
}

(cd "$work" && exec "$bin_mocapd") >"$work/mocapd.log" 2>&1 &
pids+=($!)
wait_port 7001
wait_port 7000
echo "mocapd is running (log: $work/mocapd.log); poses on 127.0.0.1:7001, sinks on :7000" >&2
# The web endpoint binds before the sink port, so it is up by now (if 8080 was free).
if (exec 3<>"/dev/tcp/127.0.0.1/8080") 2>/dev/null; then
  echo "live 3D viewer: http://127.0.0.1:8080/  (metrics: http://127.0.0.1:8080/metrics, health: /healthz)" >&2
else
  echo "the viewer's port 8080 did not open (in use?); see $work/mocapd.log" >&2
fi
"$bin_sim" stream --connect 127.0.0.1:7000 --subjects 1 --nodes 15 --rate 100 --motion walk \
  --duration 86400 >"$work/sim.log" 2>&1 &
pids+=($!)
echo "mocap-sim is streaming a walking subject; live poses follow (Ctrl-C to stop)" >&2
"$bin_client" --connect 127.0.0.1:7001 cat "$@"
