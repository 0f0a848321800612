#!/usr/bin/env bash
# export_memory.sh MOCAPD MOCAP_SIM WORKDIR: peak and retained RSS of mocapd around one offline
# CSV export of a ~30 MB take (2 subjects x 15 nodes at 500 Hz), then a BVH and a causal CSV
# export; VmHWM/VmRSS from /proc (docs/reliability.md, "Export memory"). Ports 37100-37102.
# BYTES=N sets the raw size to record (default 30000000).
set -euo pipefail
bin="$1"
sim="$2"
dir="$3"
mkdir "$dir"  # a new directory: the take and the config go there
tok=measure-token-0123456789
cat > "$dir/mocapd.toml" <<TOML
[log]
stats_interval_s = 0
[ingest]
sink_listen = "127.0.0.1:37100"
[pipeline]
workers = 2
max_subjects = 2
[skeleton]
calibration_dir = "$dir"
[serve]
pose_listen = "127.0.0.1:37101"
[control]
token = "$tok"
[outputs]
bvh_live = false
record_dir = "$dir"
[http]
listen = "127.0.0.1:37102"
TOML
"$bin" --config "$dir/mocapd.toml" > "$dir/mocapd.log" 2>&1 &
pid=$!
trap 'kill $pid 2>/dev/null || true' EXIT
for _ in $(seq 100); do curl -s -o /dev/null 127.0.0.1:37102/healthz && break; sleep 0.2; done
"$sim" stream --connect 127.0.0.1:37100 --subjects 2 --nodes 15 --rate 500 --motion walk --duration 120 > "$dir/sim.log" 2>&1 &
simpid=$!
sleep 2
curl -s -X POST -H "X-Mocap-Token: $tok" "127.0.0.1:37102/api/takes/start?name=big" ; echo
target=${BYTES:-30000000}
while :; do
  n=$(stat -c %s "$dir"/takes/big/*.mocapraw 2>/dev/null || echo 0)
  [ "$n" -ge "$target" ] && break
  sleep 1
done
curl -s -X POST -H "X-Mocap-Token: $tok" "127.0.0.1:37102/api/takes/stop"; echo
kill $simpid; wait $simpid 2>/dev/null || true
sleep 1
raw=$(stat -c %s "$dir"/takes/big/*.mocapraw)
st() { grep -E "^$1:" /proc/$pid/status | awk '{print $2}'; }
rss0=$(st VmRSS); hwm0=$(st VmHWM)
for fmt in "csv&offline=1" "bvh" "csv"; do
  t0=$(date +%s.%N)
  code=$(curl -s -o "$dir/out" -w '%{http_code}' "127.0.0.1:37102/api/takes/big/download?format=$fmt")
  t1=$(date +%s.%N)
  sleep 2
  echo "format=$fmt http=$code bytes=$(stat -c %s "$dir/out") seconds=$(echo "$t1 - $t0" | bc) raw=$raw rss_before_kib=$rss0 hwm_before_kib=$hwm0 hwm_after_kib=$(st VmHWM) rss_after_kib=$(st VmRSS)"
done
