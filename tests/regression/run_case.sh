#!/usr/bin/env bash
# run_case.sh — one replay-change-indication case (docs/reliability.md, "Replay change
# indication"): produce an output with the real tools, then compare it with the committed
# expected file.
#
#   run_case.sh filter NAME   mocap-filter --filter NAME on the fixed simulated recording
#   run_case.sh replay        mocapd --replay of data/walk.mocapraw: BVH and joint angles
#   run_case.sh replay_offline   the same with --offline (the non-causal re-solve)
#   run_case.sh names         every filter of `mocap-filter --list` has an expected file
#
# Tools from the environment (ctest sets them): MOCAP_SIM, MOCAP_FILTER, MOCAPD, PYTHON3.
# With MOCAP_REGRESSION_WRITE=DIR the decimated outputs are written to DIR instead of being
# compared: that is how regenerate.sh makes the expected files, with exactly these commands.
set -euo pipefail
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
EXPECTED="$HERE/expected"
COMPARE=("${PYTHON3:-python3}" "$HERE/compare_outputs.py")
# The fixed recording: 90 s at 100 Hz of the magnetic scenario (motion, rests and a magnetic
# disturbance, so every branch of the filters runs), seed 12.
SIM_ARGS=(csv --scenario magnetic --seed 12)
# Every 30th row (0.3 s) of a filter output and every 4th replay frame are committed: a few
# hundred KB in all, and a filter or solver change still moves most compared rows.
FILTER_EVERY=30
REPLAY_EVERY=4
# The calibration request replay makes: 1 s from 0.8 s, inside the recording's 2.2 s still
# T-pose (the filters have settled by then).
CALIBRATE_AT=0.8:1:T

DIR="$(mktemp -d /tmp/mocap-regression.XXXXXX)"
trap 'rm -rf "$DIR"' EXIT

# result KIND FILE NAME EVERY — compares FILE with expected/NAME, or writes it there decimated.
result() {
  if [[ -n "${MOCAP_REGRESSION_WRITE:-}" ]]; then
    "${COMPARE[@]}" decimate "$1" "$2" "$MOCAP_REGRESSION_WRITE/$3" --every "$4"
  else
    "${COMPARE[@]}" compare "$1" "$EXPECTED/$3" "$2" --every "$4"
  fi
}

case "${1:-}" in
  filter)
    name=${2:?filter name}
    "$MOCAP_SIM" "${SIM_ARGS[@]}" --out "$DIR/in.csv"
    "$MOCAP_FILTER" --filter "$name" --in "$DIR/in.csv" --out "$DIR/out.csv"
    result quat "$DIR/out.csv" "filter_$name.csv" "$FILTER_EVERY"
    ;;
  replay|replay_offline)
    case_name=$1
    extra=()
    if [[ $case_name == replay_offline ]]; then extra=(--offline); fi
    "$MOCAPD" --config "$HERE/replay.toml" --replay "$HERE/data/walk.mocapraw" --bvh-out "$DIR/replay.bvh" \
      --angles-out "$DIR/replay.csv" --calibrate-at "$CALIBRATE_AT" "${extra[@]}" > "$DIR/replay.log" 2>&1 \
      || { cat "$DIR/replay.log" >&2; exit 1; }
    grep -q "subject 1: calibrated" "$DIR/replay.log" || { echo "replay: no calibration:" >&2; cat "$DIR/replay.log" >&2; exit 1; }
    if [[ $case_name == replay_offline ]]; then
      # Every sample of the 15 nodes is re-solved (the recording has no node estimates).
      grep -q "offline re-solve of 2205 of 2205 samples" "$DIR/replay.log" \
        || { echo "replay --offline: not every sample re-solved:" >&2; cat "$DIR/replay.log" >&2; exit 1; }
    fi
    result bvh "$DIR/replay.bvh" "$case_name.bvh" "$REPLAY_EVERY"
    result angles "$DIR/replay.csv" "${case_name}_angles.csv" "$REPLAY_EVERY"
    ;;
  names)
    "$MOCAP_FILTER" --list | cut -d' ' -f1 | sort > "$DIR/listed"
    (cd "$EXPECTED" && ls filter_*.csv | sed 's/^filter_//; s/\.csv$//' | sort) > "$DIR/expected"
    diff "$DIR/listed" "$DIR/expected" > "$DIR/diff" || {
      echo "filters listed by mocap-filter (<) vs expected files (>): run tests/regression/regenerate.sh" >&2
      cat "$DIR/diff" >&2
      exit 1
    }
    echo "OK: an expected file for each of $(tr '\n' ' ' < "$DIR/listed")"
    ;;
  *)
    echo "usage: run_case.sh filter NAME | replay | names" >&2
    exit 2
    ;;
esac
