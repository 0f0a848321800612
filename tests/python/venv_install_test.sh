#!/usr/bin/env bash
# The Python client installs offline into a virtual environment, as clients/python/README.md
# says: python3 -m venv --system-site-packages, then pip install of the package with
# Debian's setuptools and protoc (no package index). The installed copy, not the checkout,
# then passes the framing tests and one test against the real mocapd.
#
#   venv_install_test.sh PYTHON3 REPOSITORY_ROOT   (MOCAPD_BIN, MOCAP_SIM_BIN set by ctest)
set -euo pipefail
PY="$1"
ROOT="$2"
T="$(mktemp -d)"
trap 'rm -rf "$T"' EXIT
# A copy of the two directories the package build reads, so the build writes nothing into
# the checkout (pip builds in the source tree).
mkdir -p "$T/src/clients"
cp -r "$ROOT/proto" "$T/src/"
cp -r "$ROOT/clients/python" "$T/src/clients/"
rm -rf "$T/src/clients/python/build" "$T/src/clients/python"/*.egg-info

"$PY" -m venv --system-site-packages "$T/venv"
PIP_NO_INDEX=1 PIP_DISABLE_PIP_VERSION_CHECK=1 "$T/venv/bin/python" -m pip install --no-build-isolation \
  --quiet "$T/src/clients/python"
rm -rf "$T/src"

unset PYTHONPATH MOCAPD_CLIENT_PB2_DIR
cd "$T"
"$T/venv/bin/python" - "$T/venv" <<'PY'
import sys
import mocapd_client, mocapd_client.proto as proto
venv = sys.argv[1]
assert mocapd_client.__file__.startswith(venv), mocapd_client.__file__
assert proto.pb.__file__.startswith(venv + "/") and "/_pb/" in proto.pb.__file__, proto.pb.__file__
print("installed:", mocapd_client.__file__, "messages:", proto.pb.__file__)
PY
"$T/venv/bin/python" -m pytest -q -p no:cacheprovider --rootdir "$ROOT/tests/python" \
  "$ROOT/tests/python/test_framing.py" \
  "$ROOT/tests/python/test_daemon.py::test_frames_carry_numpy_poses_of_the_subscribed_fields"
