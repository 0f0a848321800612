#!/usr/bin/env python3
"""A filter on a committed excerpt of a real recording stays under a bound: decompresses
REC.csv.gz, runs `mocap-filter --filter NAME --eval` and fails if the total RMSE (BROAD metric,
every sample with movement = 1) is not below BOUND degrees.

    real_excerpt_check.py MOCAP_FILTER REC.csv.gz NAME BOUND_DEG [ARG...]

ARGs are passed on to mocap-filter (e.g. --offline for the non-causal re-solve).

The bound has margin over today's figure: it catches a filter that falls back to the errors it
had before (tests/filter/data/README.md), not a change in the second decimal.
"""

import gzip
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile


def main():
    if len(sys.argv) < 5:
        print(__doc__, file=sys.stderr)
        return 2
    tool, rec, name, bound = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])
    extra = sys.argv[5:]
    with tempfile.TemporaryDirectory(prefix="mocap_excerpt_") as tmp:
        csv = os.path.join(tmp, "rec.csv")
        with gzip.open(rec, "rb") as src, open(csv, "wb") as dst:
            shutil.copyfileobj(src, dst)
        p = subprocess.run([tool, "--filter", name, "--in", csv, "--out", os.path.join(tmp, "est.csv"), "--eval"] + extra,
                           capture_output=True, text=True)
    if p.returncode != 0:
        print("mocap-filter failed (%d): %s" % (p.returncode, p.stderr.strip()), file=sys.stderr)
        return 1
    r = json.loads(p.stdout)
    total = r["rmse_total_deg"]
    print("%s on %s: total RMSE %.2f° over %d samples (bound %.2f°)" % (name, os.path.basename(rec), total,
                                                                      r["samples"], bound))
    if not (math.isfinite(total) and total < bound and r["samples"] > 0):
        print("FAIL: not below the bound", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
