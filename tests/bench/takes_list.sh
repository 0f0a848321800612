#!/usr/bin/env bash
# takes_list.sh MOCAPD WORKDIR: time of GET /api/takes on a store of 3,000 takes (5 listings,
# then the last page), curl time_total and reply size (docs/reliability.md, "Takes and exports").
# Ports 37110-37112.
set -euo pipefail
bin="$1"
dir="$2"
mkdir "$dir" "$dir/takes"  # a new directory
for i in $(seq -w 0 2999); do
  mkdir "$dir/takes/t$i"
  printf '{"name":"t%s","start_us":%d,"stop_us":%d,"subjects":[1],"calibration":[],"filter":"mocap","notes":"","samples":4515,"samples_lost":0}\n' "$i" "$((1000000+10#$i))" "$((2000000+10#$i))" > "$dir/takes/t$i/take.json"
done
cat > "$dir/mocapd.toml" <<TOML
[log]
stats_interval_s = 0
[ingest]
sink_listen = "127.0.0.1:37110"
[serve]
pose_listen = "127.0.0.1:37111"
[outputs]
bvh_live = false
record_dir = "$dir"
[http]
listen = "127.0.0.1:37112"
TOML
"$bin" --config "$dir/mocapd.toml" > "$dir/mocapd.log" 2>&1 &
pid=$!
trap 'kill $pid' EXIT
for _ in $(seq 100); do curl -s -o /dev/null 127.0.0.1:37112/healthz && break; sleep 0.2; done
for t in /api/takes /api/takes /api/takes /api/takes /api/takes "/api/takes?offset=2500&limit=500"; do
  curl -s -o "$dir/out" -w "$t %{http_code} %{time_total}s " "127.0.0.1:37112$t"; echo "$(stat -c %s "$dir/out") bytes"
done
