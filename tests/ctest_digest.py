#!/usr/bin/env python3
"""ctest_digest.py JUNIT_XML — after a failed ctest run, prints a short digest of each failed
test from the JUnit file ctest wrote (--output-junit): its name, its time (a timeout shows as
the test's limit) and the lines
that say why (gtest failures with the 6 lines after each, pytest "E" lines, sanitizer and
runtime errors), at most 40 lines per test. The test command's phases print it last, so a
reader who sees only the tail of a long log (a CI summary) still sees the reason."""
import re
import sys
import xml.etree.ElementTree as ET

WHY = re.compile(r"Failure$|: Failure|^E   |ERROR: \w*Sanitizer|runtime error:|LeakSanitizer|SUMMARY: |"
                 r"Assertion .*failed|terminate called|^FAILED ")
AFTER_FAILURE = 6
MOST = 40


def why(output: str) -> list[str]:
    kept, after = [], 0
    for line in output.splitlines():
        if after:
            kept.append(line)
            after -= 1
        elif WHY.search(line):
            kept.append(line)
            after = AFTER_FAILURE if line.endswith("Failure") else 0
    return kept


def main() -> int:
    try:
        root = ET.parse(sys.argv[1]).getroot()
    except (OSError, ET.ParseError, IndexError) as e:
        print(f"ctest digest: no JUnit file to read ({e})")
        return 0
    print("=== ctest digest: why each failed test failed (whole output above) ===")
    for case in root.iter("testcase"):
        if case.get("status") in ("run", "notrun", "disabled"):
            continue
        failure = case.find("failure")
        message = failure.get("message", "") if failure is not None else ""
        print(f"--- {case.get('name')}: {case.get('status')} after {float(case.get('time', 0)):.1f} s"
              + (f" ({message})" if message else ""))
        lines = why(case.findtext("system-out") or "")
        for line in lines[:MOST]:
            print("  " + line)
        if len(lines) > MOST:
            print(f"  ... {len(lines) - MOST} more lines")
    return 0


if __name__ == "__main__":
    sys.exit(main())
