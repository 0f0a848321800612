#!/bin/bash
# churn_bench.sh — normal clients' latency with and without the subscription-churn attack
# (issue 13, item 1), for one or more pose-server builds, side by side in one run.
#
#   tests/bench/churn_bench.sh CLIENT LABEL=LOADGEN[:ARGS] [LABEL=LOADGEN[:ARGS]]...
#
# CLIENT: a mocap-client with `load --churn-clients`; each LOADGEN is a serve_loadgen
# binary (e.g. one built from the commit before the fix and one after), ARGS extra options
# for it ("--max-subscribe-subjects 4096"). For each server: 10 subjects x 15 segments at
# 100 Hz, NORMAL clients measured for SECONDS_PER_PHASE without churn, then again beside
# CHURN connections that re-send Subscribe naming SUBJECTS ids, PIPELINED at a time (1900
# ids from 1000 on, two bytes each, fit the server's default max_client_message_bytes of
# 4096). Prints one markdown row per server and phase. Environment: NORMAL (50), CHURN
# (200), SUBJECTS (1900), PIPELINED (4), SECONDS_PER_PHASE (8), PORT (7191).
set -euo pipefail
client=$1
shift
normal=${NORMAL:-50} churn=${CHURN:-200} subjects=${SUBJECTS:-1900} pipelined=${PIPELINED:-4}
seconds=${SECONDS_PER_PHASE:-8} port=${PORT:-7191}
echo "| server | churn connections | frames | missing | drops | p50 ms | p99 ms | max ms | churn Subscribes answered | churn reconnects |"
echo "|---|---|---|---|---|---|---|---|---|---|"
for spec in "$@"; do
  label=${spec%%=*}
  rest=${spec#*=}
  loadgen=${rest%%:*}
  args=""
  [[ $rest == *:* ]] && args=${rest#*:}
  # shellcheck disable=SC2086
  "$loadgen" --port "$port" --subjects 10 --segments 15 --rate 100 --duration $((2 * seconds + 30)) $args \
    > /dev/null 2>&1 &
  server=$!
  sleep 1
  for c in 0 "$churn"; do
    j=$("$client" --connect "127.0.0.1:$port" load --clients "$normal" --duration "$seconds" --json \
          --churn-clients "$c" --churn-subjects "$subjects" --churn-pipelined "$pipelined" || true)
    python3 -c '
import json, sys
j = json.loads(sys.argv[1])
f = lambda v: "—" if v is None else "%.2f" % v
print("| %s | %s | %d | %d | %d | %s | %s | %s | %d | %d |" % (sys.argv[2], sys.argv[3], j["frames"],
      j["missing_frames"], j["drops"], f(j["p50_ms"]), f(j["p99_ms"]), f(j["max_ms"]), j["churn_subscribes"],
      j["churn_reconnects"]))' "$j" "$label" "$c"
  done
  kill "$server" 2>/dev/null || true
  wait "$server" 2>/dev/null || true
  port=$((port + 1))
done
