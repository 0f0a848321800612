#!/usr/bin/env python3
"""compare_outputs.py — numeric comparison of an output file with its committed expected file.

  compare_outputs.py compare KIND EXPECTED ACTUAL [--every N]
  compare_outputs.py decimate KIND IN OUT --every N
  compare_outputs.py selftest QUAT OTHER_QUAT [--angles CSV] [--bvh BVH]

KIND says which tolerance each value gets (docs/reliability.md, "Replay change indication"):
  quat   mocap-filter output, t,qw,qx,qy,qz: t within 1e-9 s, each quaternion component
         within 1e-6; q and -q are the same rotation, so a row also matches with every
         component of ACTUAL negated.
  angles joint-angle CSV (serve/angles_csv.hpp): subject and sync exact, t_s within 1e-9 s,
         angles within one unit of their printed last digit (0.001 deg), modulo 360.
  bvh    BVH text: every token of the HIERARCHY and MOTION sections; words exact, numbers
         within one unit of the expected token's last printed digit, rotation channels
         modulo 360.

Why not byte for byte: the sanitizer builds compile at other optimisation levels, and a
compiler may fold, contract (FMA) or call libm differently at each, which moves the last
bits of a double. Such a difference is far below the tolerances above; a change of a
filter, of the solver or of a parameter is far above them. A printed value rounds, so two
values a hair apart on either side of a rounding boundary print one unit apart: that is why
the printed-precision tolerance is one unit of the last digit, not half of one.

--every N keeps the data rows (MOTION lines for a BVH) 0, N, 2N... of a file: the committed
expected files are decimated so they stay small, and ACTUAL is decimated the same way
before the comparison. The header (and a BVH's "Frames:" count) stays as the full file had it.

Exit status: 0 = equal within tolerance, 1 = a difference (the first one is printed with its
position, both values and the tolerance), 2 = usage or unreadable file.
"""

import argparse
import math
import os
import re
import sys
import tempfile

TIME_TOL = 1e-9
QUAT_TOL = 1e-6
NUMBER = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")


class Difference(Exception):
    pass


def printed_unit(token):
    """One unit of the last printed digit of a number token ("12.345" -> 0.001, "7" -> 1)."""
    mantissa, _, exponent = token.lower().partition("e")
    decimals = len(mantissa.partition(".")[2])
    return 10.0 ** (-decimals + (int(exponent) if exponent else 0))


def angle_diff(a, b):
    d = abs(a - b) % 360.0
    return min(d, 360.0 - d)


def check(where, name, expected, actual, diff, tol):
    if not diff <= tol * (1 + 1e-9):  # also catches NaN
        raise Difference(
            f"{where}, {name}: expected {expected}, got {actual}, |diff| = {diff:.3g} > tolerance {tol:.3g}"
        )


# --- CSV kinds -------------------------------------------------------------------------------


def read_lines(path):
    with open(path, encoding="ascii") as f:
        return f.read().splitlines()


def csv_rows(path, every):
    lines = read_lines(path)
    if not lines:
        raise Difference(f"{path}: empty file")
    rows = [(i + 2, line) for i, line in enumerate(lines[1:])]  # (line number, text)
    return lines[0], rows[::every]


def compare_quat_row(where, names, e, a):
    qcols = [i for i, n in enumerate(names) if n in ("qw", "qx", "qy", "qz")]
    for i, n in enumerate(names):
        if i not in qcols:
            check(where, f"column {i + 1} '{n}'", e[i], a[i], abs(float(e[i]) - float(a[i])), TIME_TOL)
    ev = [float(e[i]) for i in qcols]
    av = [float(a[i]) for i in qcols]
    # Same rotation if every component matches for q or for -q; report against the closer sign.
    sign = 1.0 if sum(abs(x - y) for x, y in zip(ev, av)) <= sum(abs(x + y) for x, y in zip(ev, av)) else -1.0
    for i, x, y in zip(qcols, ev, av):
        shown = a[i] if sign > 0 else f"{a[i]} (row negated: -q is the same rotation)"
        check(where, f"column {i + 1} '{names[i]}'", e[i], shown, abs(x - sign * y), QUAT_TOL)


def compare_angles_row(where, names, e, a):
    for i, n in enumerate(names):
        col = f"column {i + 1} '{n}'"
        if n in ("subject", "sync"):
            if e[i] != a[i]:
                raise Difference(f"{where}, {col}: expected {e[i]}, got {a[i]} (must be equal)")
        elif n == "t_s":
            check(where, col, e[i], a[i], abs(float(e[i]) - float(a[i])), TIME_TOL)
        else:
            check(where, col, e[i], a[i], angle_diff(float(e[i]), float(a[i])), printed_unit(e[i]))


def compare_csv(kind, expected, actual, every):
    e_header, e_rows = csv_rows(expected, 1)
    a_header, a_rows = csv_rows(actual, every)
    if e_header != a_header:
        raise Difference(f"{actual}: line 1 (header) differs:\n  expected {e_header}\n  got      {a_header}")
    names = e_header.split(",")
    row_check = compare_quat_row if kind == "quat" else compare_angles_row
    for (e_no, e_line), (a_no, a_line) in zip(e_rows, a_rows):
        e, a = e_line.split(","), a_line.split(",")
        where = f"{actual}: line {a_no} (expected file line {e_no})"
        if len(e) != len(names) or len(a) != len(names):
            raise Difference(f"{where}: {len(a)} values, expected file has {len(e)}, header {len(names)}")
        row_check(where, names, e, a)
    if len(e_rows) != len(a_rows):
        raise Difference(f"{actual}: {len(a_rows)} compared rows (every {every}), expected {len(e_rows)}")
    return len(e_rows) * len(names)


# --- BVH -----------------------------------------------------------------------------------


def bvh_sections(path, every):
    """(header lines, motion lines, rotation flags per motion column) of a BVH file."""
    lines = read_lines(path)
    try:
        start = next(i for i, line in enumerate(lines) if line.startswith("Frame Time:")) + 1
    except StopIteration:
        raise Difference(f"{path}: no 'Frame Time:' line (not a BVH file?)")
    rotation = []
    for line in lines[:start]:
        words = line.split()
        if words and words[0] == "CHANNELS":
            rotation += [w.endswith("rotation") for w in words[2:]]
    motion = [(start + i + 1, line) for i, line in enumerate(lines[start:])]
    return [(i + 1, line) for i, line in enumerate(lines[:start])], motion[::every], rotation


def compare_tokens(where, e_line, a_line, rotation):
    e, a = e_line.split(), a_line.split()
    if len(e) != len(a):
        raise Difference(f"{where}: {len(a)} tokens, expected {len(e)}")
    for i, (x, y) in enumerate(zip(e, a)):
        name = f"token {i + 1}"
        if not NUMBER.match(x) or not NUMBER.match(y):
            if x != y:
                raise Difference(f"{where}, {name}: expected '{x}', got '{y}'")
            continue
        is_rot = rotation is not None and i < len(rotation) and rotation[i]
        diff = angle_diff(float(x), float(y)) if is_rot else abs(float(x) - float(y))
        check(where, name + (" (rotation, deg)" if is_rot else ""), x, y, diff, printed_unit(x))


def compare_bvh(expected, actual, every):
    e_head, e_motion, rotation = bvh_sections(expected, 1)
    a_head, a_motion, _ = bvh_sections(actual, every)
    if len(e_head) != len(a_head):
        raise Difference(f"{actual}: HIERARCHY has {len(a_head)} lines, expected {len(e_head)}")
    for (no, e_line), (_, a_line) in zip(e_head, a_head):
        compare_tokens(f"{actual}: line {no}", e_line, a_line, None)
    for (e_no, e_line), (a_no, a_line) in zip(e_motion, a_motion):
        compare_tokens(f"{actual}: line {a_no} (expected file line {e_no})", e_line, a_line, rotation)
    if len(e_motion) != len(a_motion):
        raise Difference(f"{actual}: {len(a_motion)} compared MOTION lines (every {every}), expected {len(e_motion)}")
    return len(e_motion) * len(rotation)


def compare(kind, expected, actual, every=1):
    if kind == "bvh":
        return compare_bvh(expected, actual, every)
    return compare_csv(kind, expected, actual, every)


def decimate(kind, src, dst, every):
    lines = read_lines(src)
    if kind == "bvh":
        head, motion, _ = bvh_sections(src, every)
        kept = [line for _, line in head] + [line for _, line in motion]
    else:
        kept = lines[:1] + lines[1:][::every]
    with open(dst, "w", encoding="ascii") as f:
        f.write("\n".join(kept) + "\n")


# --- self-test -------------------------------------------------------------------------------


def perturbed_copy(src, dst, line_no, column, delta, sep):
    """Copies src to dst with the value at (line_no, column) moved by delta."""
    lines = read_lines(src)
    values = lines[line_no - 1].split(sep)
    values[column] = repr(float(values[column]) + delta)
    lines[line_no - 1] = sep.join(values)
    with open(dst, "w", encoding="ascii") as f:
        f.write("\n".join(lines) + "\n")


def expect_difference(kind, expected, actual, must_name):
    try:
        compare(kind, expected, actual)
    except Difference as d:
        if must_name not in str(d):
            raise SystemExit(f"selftest: difference reported at the wrong place: {d} (want '{must_name}')")
        print(f"selftest: detected as expected: {d}")
        return
    raise SystemExit(f"selftest: {actual} vs {expected} ({kind}) passed but must fail")


def selftest(quat, other, angles, bvh):
    """Proves that the comparison fails: on a value moved by twice its tolerance, and on
    another filter's output; and that it passes on a value moved by half its tolerance."""
    with tempfile.TemporaryDirectory() as tmp:
        p = os.path.join(tmp, "p")
        compare("quat", quat, quat)
        perturbed_copy(quat, p, 20, 2, 0.5 * QUAT_TOL, ",")
        compare("quat", quat, p)
        perturbed_copy(quat, p, 20, 2, 2 * QUAT_TOL, ",")
        expect_difference("quat", quat, p, "line 20 (expected file line 20), column 3 'qx'")
        expect_difference("quat", quat, other, "column")
        if angles:
            compare("angles", angles, angles)
            perturbed_copy(angles, p, 15, 7, 0.0004, ",")
            compare("angles", angles, p)
            perturbed_copy(angles, p, 15, 7, 0.002, ",")
            name = read_lines(angles)[0].split(",")[7]
            expect_difference("angles", angles, p, f"line 15 (expected file line 15), column 8 '{name}'")
        if bvh:
            compare("bvh", bvh, bvh)
            motion_line = len(read_lines(bvh)) - 3
            perturbed_copy(bvh, p, motion_line, 10, 0.02, " ")
            expect_difference("bvh", bvh, p, f"line {motion_line} (expected file line {motion_line}), token 11")
    print("selftest: PASS")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("compare")
    c.add_argument("kind", choices=["quat", "angles", "bvh"])
    c.add_argument("expected")
    c.add_argument("actual")
    c.add_argument("--every", type=int, default=1)
    d = sub.add_parser("decimate")
    d.add_argument("kind", choices=["quat", "angles", "bvh"])
    d.add_argument("src")
    d.add_argument("dst")
    d.add_argument("--every", type=int, required=True)
    s = sub.add_parser("selftest")
    s.add_argument("quat", help="an expected filter output")
    s.add_argument("other", help="another filter's expected output")
    s.add_argument("--angles", help="an expected joint-angle CSV")
    s.add_argument("--bvh", help="an expected BVH file")
    args = ap.parse_args()
    try:
        if args.cmd == "compare":
            n = compare(args.kind, args.expected, args.actual, args.every)
            print(f"OK {args.actual}: {n} values within tolerance of {args.expected}")
        elif args.cmd == "decimate":
            decimate(args.kind, args.src, args.dst, args.every)
        else:
            selftest(args.quat, args.other, args.angles, args.bvh)
    except Difference as diff:
        print(f"FIRST DIFFERENCE: {diff}", file=sys.stderr)
        return 1
    except OSError as e:
        print(f"compare_outputs.py: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
