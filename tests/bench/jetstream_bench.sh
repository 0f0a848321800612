#!/bin/bash
# jetstream_bench.sh — durable takes (docs/outputs.md, "Durable takes (JetStream)") on this
# host: raw bytes per subject per second on the JetStream stream MOCAP_RAW and the
# publish-to-acknowledgement latency (p50/p99), with nats-server -js (file store in a temporary directory), mocapd and mocap-sim on loopback.
#
#   tests/bench/jetstream_bench.sh MOCAPD MOCAP_SIM MOCAP_CLIENT
#
# Environment: SUBJECTS (1), SECONDS_RUN (20), PORT_BASE (7300: nats, monitor, sink, pose).
# Prints one markdown row: subjects, samples acked, stream messages and bytes (from the
# server's /jsz), bytes per subject per second, mean message size, ack p50/p99/max.
set -euo pipefail
mocapd=$1 sim=$2 client=$3
subjects=${SUBJECTS:-1} seconds=${SECONDS_RUN:-20} base=${PORT_BASE:-7300}
nats_port=$base mon_port=$((base + 1)) sink_port=$((base + 2)) pose_port=$((base + 3))
dir=$(mktemp -d)
pids=()
cleanup() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; wait 2>/dev/null || true; rm -rf "$dir"; }
trap cleanup EXIT
nats-server -a 127.0.0.1 -p "$nats_port" -m "$mon_port" -js -sd "$dir/js" --user bench --pass bench-pw \
  > "$dir/nats.log" 2>&1 &
pids+=($!)
cat > "$dir/mocapd.toml" <<TOML
[log]
level = "warn"
stats_interval_s = 0
[ingest]
sink_listen = "127.0.0.1:$sink_port"
[pipeline]
max_subjects = $subjects
[skeleton]
calibration_dir = "$dir"
[serve]
pose_listen = "127.0.0.1:$pose_port"
[outputs]
bvh_live = false
[http]
enabled = false
[cluster]
nats_url = "nats://127.0.0.1:$nats_port"
site = "bench"
user = "bench"
password = "bench-pw"
TOML
sleep 1  # nats-server and its JetStream store come up
"$mocapd" --config "$dir/mocapd.toml" > "$dir/mocapd.log" 2>&1 &
pids+=($!)
sleep 1
"$sim" stream --connect "127.0.0.1:$sink_port" --rate 100 --subjects "$subjects" --duration "$seconds" \
  > "$dir/sim.log" 2>&1
sleep 2  # the last acknowledgements
stats=$("$client" --connect "127.0.0.1:$pose_port" stats --json)
jsz=$(curl -s "http://127.0.0.1:$mon_port/jsz?streams=true")
python3 - "$stats" "$jsz" "$subjects" "$seconds" <<'PY'
import json, sys
stats, jsz = json.loads(sys.argv[1]), json.loads(sys.argv[2])
subjects, seconds = int(sys.argv[3]), float(sys.argv[4])
counters = stats["counters"]
lat = next(l for l in stats["latencies"] if l["stage"] == "cluster_raw_ack")
stream = next(s for a in jsz["account_details"] for s in a["stream_detail"] if s["name"] == "MOCAP_RAW")
msgs, nbytes = stream["state"]["messages"], stream["state"]["bytes"]
print("| subjects | samples acked | dropped | failed | stream messages | stream bytes | bytes/subject/s | bytes/message | ack p50 ms | ack p99 ms | ack max ms |")
print("|---|---|---|---|---|---|---|---|---|---|---|")
print("| %d | %d | %d | %d | %d | %d | %.0f | %.0f | %.2f | %.2f | %.2f |" % (
    subjects, counters["cluster.raw_samples_acked"], counters["cluster.raw_samples_dropped"],
    counters["cluster.raw_samples_failed"], msgs, nbytes, nbytes / subjects / seconds, nbytes / max(msgs, 1),
    lat["p50_us"] / 1000, lat["p99_us"] / 1000, lat["max_us"] / 1000))
PY
