#!/usr/bin/env bash
# regenerate.sh — rebuilds the expected files of the replay change indication
# (docs/reliability.md, "Replay change indication") after an intended numerical change.
#
#   tests/regression/regenerate.sh [BUILD_DIR]          (default: build)
#   tests/regression/regenerate.sh --record-raw [BUILD_DIR]
#
# Builds mocap-sim, mocap-filter and mocapd in BUILD_DIR, runs every case of run_case.sh (the
# commands the ctests run) twice into two scratch directories, fails unless both runs gave
# identical files (the outputs must be deterministic, or the test would be flaky), then
# replaces expected/ and shows `git diff --stat`: review and commit that diff together with
# the change that caused it.
#
# --record-raw first re-records the replay input, data/walk.mocapraw: the real daemon on
# loopback fed by `mocap-sim stream` (1 subject, 15 nodes, 50 Hz, 2.2 s still T-pose then
# the built-in walk, 3.4 s in all). Live timing differs run to run, so a new recording changes the
# replay's expected files; do it only when the raw format changes.
set -euo pipefail
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
ROOT="$(cd "$HERE/../.." && pwd)"
record_raw=0
if [[ "${1:-}" == "--record-raw" ]]; then record_raw=1; shift; fi
BUILD="$(cd "${1:-$ROOT/build}" && pwd)"

cmake --build "$BUILD" -j2 --target mocap-sim mocap-filter mocapd
tool() { find "$BUILD" -type f -perm -u+x -name "$1" -print -quit; }
export MOCAP_SIM MOCAP_FILTER MOCAPD PYTHON3=python3 PYTHONDONTWRITEBYTECODE=1
MOCAP_SIM=$(tool mocap-sim) MOCAP_FILTER=$(tool mocap-filter) MOCAPD=$(tool mocapd)
[[ -x "$MOCAP_SIM" && -x "$MOCAP_FILTER" && -x "$MOCAPD" ]] || { echo "tools not found in $BUILD" >&2; exit 1; }

SCRATCH="$(mktemp -d /tmp/mocap-regenerate.XXXXXX)"
DAEMON=""
cleanup() {
  [[ -n "$DAEMON" ]] && kill -9 "$DAEMON" 2>/dev/null
  rm -rf "$SCRATCH"
}
trap cleanup EXIT

if [[ $record_raw == 1 ]]; then
  port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
  SINK=$(port)
  mkdir "$SCRATCH/raw"
  # Only the sink port and the raw recorder: the other listeners are off or on free ports.
  cat > "$SCRATCH/record.toml" <<TOML
[log]
stats_interval_s = 0
[ingest]
sink_listen = "127.0.0.1:$SINK"
[skeleton]
calibration_dir = "$SCRATCH/raw"
auto_calibrate = "off"
[serve]
pose_listen = "127.0.0.1:$(port)"
[outputs]
bvh_live = false
record_dir = "$SCRATCH/raw"
raw_record = true
record_flush_interval_s = 0.2
[http]
enabled = false
TOML
  "$MOCAPD" --config "$SCRATCH/record.toml" > "$SCRATCH/record.log" 2>&1 &
  DAEMON=$!
  for _ in $(seq 100); do (echo > "/dev/tcp/127.0.0.1/$SINK") 2>/dev/null && break; sleep 0.1; done
  "$MOCAP_SIM" stream --connect "127.0.0.1:$SINK" --subjects 1 --nodes 15 --rate 50 --duration 3.4 \
    --calibrate-s 2.2 --motion walk --seed 12
  kill -TERM "$DAEMON"
  wait "$DAEMON"
  DAEMON=""
  raw=("$SCRATCH"/raw/raw-*.mocapraw)
  [[ ${#raw[@]} == 1 && -s "${raw[0]}" ]] || { echo "expected one raw recording" >&2; cat "$SCRATCH/record.log" >&2; exit 1; }
  mkdir -p "$HERE/data"
  cp "${raw[0]}" "$HERE/data/walk.mocapraw"
fi

filters=$("$MOCAP_FILTER" --list | cut -d' ' -f1)
for run in 1 2; do
  export MOCAP_REGRESSION_WRITE="$SCRATCH/run$run"
  mkdir "$MOCAP_REGRESSION_WRITE"
  for name in $filters; do "$HERE/run_case.sh" filter "$name"; done
  "$HERE/run_case.sh" replay
  "$HERE/run_case.sh" replay_offline
done
diff -r "$SCRATCH/run1" "$SCRATCH/run2" || { echo "NOT DETERMINISTIC: two runs differ (above)" >&2; exit 1; }
echo "deterministic: two runs gave identical files"

rm -rf "$HERE/expected"
cp -r "$SCRATCH/run1" "$HERE/expected"
du -ch "$HERE/expected"/* "$HERE/data"/* | tail -1 | sed 's/total/in expected\/ and data\/ (keep it to a few hundred KB)/'
git -C "$ROOT" status --short -- tests/regression/expected tests/regression/data
git -C "$ROOT" diff --stat -- tests/regression/expected tests/regression/data
