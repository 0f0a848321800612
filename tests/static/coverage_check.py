#!/usr/bin/env python3
"""Tests mirror the sources (docs/style.md): every server/**/X.cpp has a tests/**/X_test.cpp,
or a line in tests/coverage_map.txt naming the tests that cover it and why it has no test of
its own. Fails on a source in neither place, and on a map line that is stale: its source is
gone or has its own test now, or a test file it names does not exist.

  tests/static/coverage_check.py [REPO_ROOT]
  tests/static/coverage_check.py --self-test   plants each kind of problem in a scratch tree
                                               and requires it to be found, then checks the repo
"""

import pathlib
import sys
import tempfile


def problems_of(root):
    tests = root / "tests"
    sources = sorted(p.relative_to(root / "server").as_posix() for p in (root / "server").rglob("*.cpp"))
    own_tests = {p.name[: -len("_test.cpp")] for p in tests.rglob("*_test.cpp")}
    problems = []
    mapped = {}
    for number, line in enumerate((tests / "coverage_map.txt").read_text().splitlines(), 1):
        if not line.strip() or line.startswith("#"):
            continue
        fields = [f.strip() for f in line.split("|")]
        if len(fields) != 3 or not all(fields):
            problems.append(f"coverage_map.txt:{number}: want 'source | tests | why', got: {line}")
            continue
        source, covering, why = fields
        if source in mapped:
            problems.append(f"coverage_map.txt:{number}: {source} is listed twice")
        mapped[source] = number
        if source not in sources:
            problems.append(f"coverage_map.txt:{number}: server/{source} does not exist (remove the line)")
        elif pathlib.PurePath(source).stem in own_tests:
            problems.append(f"coverage_map.txt:{number}: server/{source} has its own test now (remove the line)")
        for test in covering.split():
            if not (tests / test).is_file():
                problems.append(f"coverage_map.txt:{number}: tests/{test} does not exist")
    for source in sources:
        if pathlib.PurePath(source).stem not in own_tests and source not in mapped:
            problems.append(f"server/{source} has no tests/**/{pathlib.PurePath(source).stem}_test.cpp and no line "
                            f"in tests/coverage_map.txt (the tests that cover it, and why it has none of its own)")
    covered = sum(1 for s in sources if pathlib.PurePath(s).stem in own_tests)
    summary = (f"coverage_check: {len(sources)} server sources, {covered} with a test of their own, "
               f"{len(mapped)} covered by others (tests/coverage_map.txt); {len(problems)} problem(s)")
    return problems, summary


def self_test():
    """Each planted problem must be reported, and a clean tree must pass."""
    cases = {
        "unmapped source": ({"server/a/x.cpp": ""}, "", "no tests/**/x_test.cpp"),
        "gone source": ({}, "a/y.cpp | a/y_test.cpp | why\n", "does not exist (remove"),
        "own test now": ({"server/a/x.cpp": "", "tests/a/x_test.cpp": ""}, "a/x.cpp | a/x_test.cpp | why\n",
                         "has its own test now"),
        "missing test file": ({"server/a/x.cpp": ""}, "a/x.cpp | a/nothing_test.cpp | why\n", "tests/a/nothing"),
        "no reason": ({"server/a/x.cpp": "", "tests/a/other.cpp": ""}, "a/x.cpp | a/other.cpp |\n", "want 'source"),
        "clean": ({"server/a/x.cpp": "", "tests/a/other.cpp": ""}, "a/x.cpp | a/other.cpp | covered there\n", None),
    }
    failed = 0
    for name, (files, mapping, expected) in cases.items():
        with tempfile.TemporaryDirectory() as d:
            root = pathlib.Path(d)
            for path, text in files.items():
                (root / path).parent.mkdir(parents=True, exist_ok=True)
                (root / path).write_text(text)
            (root / "server").mkdir(exist_ok=True)
            (root / "tests").mkdir(exist_ok=True)
            (root / "tests" / "coverage_map.txt").write_text(mapping)
            problems, _ = problems_of(root)
            ok = (not problems) if expected is None else any(expected in p for p in problems)
            if not ok:
                failed += 1
                print(f"self-test '{name}': expected {expected!r}, got {problems}")
    return failed == 0


def main():
    args = sys.argv[1:]
    if args and args[0] == "--self-test":
        if not self_test():
            return 1
        args = args[1:]
    root = pathlib.Path(args[0] if args else pathlib.Path(__file__).resolve().parents[2])
    problems, summary = problems_of(root)
    for p in problems:
        print(p)
    print(summary)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
