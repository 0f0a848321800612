#!/usr/bin/env bash
# Static analysis of the product sources: clang-tidy (checks in /.clang-tidy) and cppcheck
# (options below, suppressions in tests/static/cppcheck.supp), over server/, clients/ and
# firmware/ as compiled by one build's compile_commands.json. Generated code (protobuf
# *.pb.cc, the embedded default config) lives in the build directory and is not analysed;
# neither are third-party headers. Tests are not analysed either (gtest macros).
#
#   tests/static/run_static.sh [BUILD_DIR]        default BUILD_DIR: build/
#
#   MOCAP_STATIC_JOBS=N       parallel clang-tidy processes and cppcheck threads (default 2)
#   MOCAP_STATIC_TOOLS="..."  subset of "clang-tidy cppcheck" (default both)
#   MOCAP_STATIC_FILES=REGEX  only the sources whose path matches REGEX (default all)
#   MOCAP_STATIC_FULL=1       run clang-tidy on every unit, ignoring the record of clean ones
#   MOCAP_STATIC_UPDATE=1     after a clean run, rewrite tests/static/tidy-clean.txt (commit it)
#
# clang-tidy skips a translation unit whose key is recorded as clean, in the committed
# tests/static/tidy-clean.txt or in this machine's cache ($MOCAP_STATIC_CACHE, default
# ~/.cache/mocapd-static). The key is a hash of everything clang-tidy's result depends on:
# the unit as clang preprocesses it with its compile command (so every included header,
# ours and the system's), that command, .clang-tidy, this script and the clang-tidy version.
# Any change to one of them makes the unit's key new, and the unit is analysed again.
#
# The build must have been built at least up to the protobuf headers (mocap_proto), since
# the sources include them. Prints every finding once (a header finding is reported by every
# translation unit that includes it; duplicates are dropped), a count per check, the time
# per tool, and exits 1 if there is any finding, 2 if a tool or the database is missing.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
BUILD="$(cd "${1:-$ROOT/build}" && pwd)"
DB="$BUILD/compile_commands.json"
JOBS="${MOCAP_STATIC_JOBS:-2}"
TOOLS="${MOCAP_STATIC_TOOLS:-clang-tidy cppcheck}"
FILTER="${MOCAP_STATIC_FILES:-.}"
OUT="$BUILD/static"
SUPP="$ROOT/tests/static/cppcheck.supp"
KNOWN="$ROOT/tests/static/known.txt"

say() { printf '[static] %s\n' "$*"; }

if [[ ! -f "$DB" ]]; then
  say "no $DB (configure with CMAKE_EXPORT_COMPILE_COMMANDS=ON, the project default)"
  exit 2
fi
rm -rf "$OUT"
mkdir -p "$OUT/tidy"

# The product's translation units: under ROOT/{server,clients,firmware}, not generated.
python3 - "$DB" "$ROOT" "$BUILD" "$FILTER" "$OUT" <<'PY'
import json, os, re, sys
db, root, build, pattern, out = sys.argv[1:]
# A source compiled into several targets (the wire library's C files: the library, its
# test variants, the 32-bit self-test) is analysed once, as the product library compiles it:
# entries of targets defined under tests/ come last, and the first entry of each file wins.
def test_target(e):
    return os.path.relpath(e["directory"], build).split(os.sep)[0] == "tests"
entries, seen = [], set()
for e in sorted(json.load(open(db)), key=test_target):
    f = os.path.normpath(os.path.join(e["directory"], e["file"]))
    rel = os.path.relpath(f, root)
    if f.startswith(build + os.sep) or rel.split(os.sep)[0] not in ("server", "clients", "firmware"):
        continue
    if f.endswith(".pb.cc") or not re.search(pattern, rel) or f in seen:
        continue
    seen.add(f)
    entries.append(dict(e, file=f))
with open(os.path.join(out, "compile_commands.json"), "w") as fh:
    json.dump(entries, fh, indent=1)
with open(os.path.join(out, "files.txt"), "w") as fh:
    fh.write("".join(e["file"] + "\n" for e in entries))
PY
nfiles=$(wc -l <"$OUT/files.txt")
if ((nfiles == 0)); then
  say "no product sources in $DB match '$FILTER'"
  exit 2
fi
say "$nfiles translation units from $DB"

RECORD="$ROOT/tests/static/tidy-clean.txt"
CACHE="${MOCAP_STATIC_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/mocapd-static}/tidy-clean.txt"
TIDY="$(command -v clang-tidy-14 || command -v clang-tidy || true)"

# tidy_keys plan: $OUT/keys.tsv (file, key) for every unit, and $OUT/tidy-files.txt, the
# units whose key is in neither the record nor the cache.
# tidy_keys verify: $OUT/keys-after.tsv, the keys of the analysed units computed again after
# the analysis; a unit whose sources changed while it was analysed is not recorded.
tidy_keys() {
  python3 - "$1" "$OUT" "$ROOT" "$BUILD" "$JOBS" "$TIDY" "$RECORD" "$CACHE" "${MOCAP_STATIC_FULL:-0}" \
    "${BASH_SOURCE[0]}" <<'PY'
import concurrent.futures, hashlib, json, os, shlex, subprocess, sys
mode, out, root, build, jobs, tidy, record, cache, full, script = sys.argv[1:]
clangxx = "clang++-14" if subprocess.run(["sh", "-c", "command -v clang++-14"], capture_output=True).returncode == 0 else "clang++"
def norm(text):
    return text.replace(build, "@BUILD@").replace(root, "@ROOT@")
salt = hashlib.sha256()
salt.update(subprocess.run([tidy, "--version"], capture_output=True, text=True).stdout.encode())
for f in (os.path.join(root, ".clang-tidy"), script):
    salt.update(open(f, "rb").read())
def key(e):
    args = e["arguments"] if "arguments" in e else shlex.split(e["command"])
    cmd, skip = [clangxx if args[0].endswith("++") else "clang-14"], False
    for a in args[1:]:
        if skip or a in ("-c", e["file"]) or a.startswith("-o"):
            skip = a == "-o"
            continue
        cmd.append(a)
    cmd += ["-Wno-unknown-warning-option", "-UNDEBUG", "-E", "-P", e["file"]]
    pp = subprocess.run(cmd, cwd=e["directory"], capture_output=True)
    if pp.returncode != 0:
        return None  # not preprocessable here: always analysed, clang-tidy reports why
    h = salt.copy()
    h.update(norm(" ".join(cmd)).encode())
    h.update(norm(pp.stdout.decode("utf-8", "replace")).encode())
    return h.hexdigest()
entries = json.load(open(os.path.join(out, "compile_commands.json")))
if mode == "verify":
    analysed = set(l.strip() for l in open(os.path.join(out, "tidy-files.txt")))
    entries = [e for e in entries if e["file"] in analysed]
with concurrent.futures.ThreadPoolExecutor(int(jobs)) as ex:
    keys = list(ex.map(key, entries))
if mode == "verify":
    with open(os.path.join(out, "keys-after.tsv"), "w") as kt:
        kt.writelines(f"{e['file']}\t{k or '-'}\n" for e, k in zip(entries, keys))
    sys.exit(0)
clean = set()
if full != "1":
    for f in (record, cache):
        if os.path.exists(f):
            clean.update(line.split()[0] for line in open(f) if line.strip() and not line.startswith("#"))
todo = 0
with open(os.path.join(out, "keys.tsv"), "w") as kt, open(os.path.join(out, "tidy-files.txt"), "w") as tf:
    for e, k in zip(entries, keys):
        kt.write(f"{e['file']}\t{k or '-'}\n")
        if k is None or k not in clean:
            tf.write(e["file"] + "\n")
            todo += 1
print(f"[static] clang-tidy: {len(entries) - todo} of {len(entries)} units unchanged since a clean analysis; {todo} to analyse")
PY
}

# tidy_record: the units analysed without a finding join the cache; with
# MOCAP_STATIC_UPDATE=1 the record is rewritten: its entries for units that no longer exist
# or now have findings go, this run's clean units are written with their current keys.
tidy_record() {
  python3 - "$OUT" "$ROOT" "$RECORD" "$CACHE" "$1" <<'PY'
import os, re, sys
out, root, record, cache, update = sys.argv[1:]
finding = re.compile(r"^[^ ]+:[0-9]+:[0-9]+: (warning|error): .*\[[^]]+\]$", re.M)
analysed = set(l.strip() for l in open(os.path.join(out, "tidy-files.txt")))
after = dict(l.rstrip("\n").split("\t") for l in open(os.path.join(out, "keys-after.tsv")))
clean, dirty = {}, set()
for line in open(os.path.join(out, "keys.tsv")):
    f, k = line.rstrip("\n").split("\t")
    if k == "-" or (f in analysed and after.get(f) != k):
        dirty.add(f)  # not preprocessable, or its sources changed while it was analysed
        continue
    if f in analysed:
        log = os.path.join(out, "tidy", f.replace("/", "_") + ".log")
        if finding.search(open(log, errors="replace").read()):
            dirty.add(f)
            continue
    clean[os.path.relpath(f, root)] = k
os.makedirs(os.path.dirname(cache), exist_ok=True)
with open(cache, "a") as c:
    c.writelines(f"{k} {f}\n" for f, k in clean.items() if os.path.join(root, f) in analysed)
if update == "1":
    rows = {}
    if os.path.exists(record):
        for line in open(record):
            if line.strip() and not line.startswith("#"):
                k, f = line.split()
                rows[f] = k
    dirty_rel = {os.path.relpath(f, root) for f in dirty}
    rows = {f: k for f, k in rows.items() if f not in dirty_rel and os.path.exists(os.path.join(root, f))}
    rows.update(clean)
    with open(record, "w") as r:
        r.write("# Translation units clang-tidy analysed without a finding, by key (tests/static/run_static.sh\n"
                "# explains the key; MOCAP_STATIC_UPDATE=1 rewrites this file). A listed key is not analysed again.\n")
        r.writelines(f"{rows[f]} {f}\n" for f in sorted(rows))
    print(f"[static] {record}: {len(rows)} units recorded clean")
PY
}

status=0
hfilter="^$ROOT/(server|clients|firmware)/"

run_tidy() {
  local tidy="$TIDY"
  if [[ -z "$tidy" ]]; then say "clang-tidy not found (Debian package clang-tidy)"; return 2; fi
  local t0=$SECONDS
  tidy_keys plan
  # One process per translation unit, each into its own log so outputs never interleave.
  # -UNDEBUG: the analyser takes assert()s as facts, which removes impossible paths.
  # The build uses g++ options clang does not know; they are not findings.
  export tidy OUT hfilter
  # shellcheck disable=SC2016
  xargs -r -a "$OUT/tidy-files.txt" -P "$JOBS" -I{} sh -c '
    log="$OUT/tidy/$(printf %s "$1" | tr / _).log"
    "$tidy" -p "$OUT" --quiet --header-filter="$hfilter" \
      --extra-arg=-Wno-unknown-warning-option --extra-arg=-UNDEBUG "$1" >"$log" 2>&1 || rc=$?
    # 1 is "findings"; a signal or any other code is a tool failure, reported as a finding.
    if [ "${rc:-0}" -gt 1 ]; then echo "$1:1:1: error: clang-tidy exited with $rc [clang-tidy-failure]" >>"$log"; fi
  ' sh {}
  # A finding: "path:line:col: warning|error: message [check]". Keep each once.
  cat "$OUT"/tidy/*.log 2>/dev/null | grep -E '^[^ ]+:[0-9]+:[0-9]+: (warning|error): .*\[[^]]+\]$' \
    | sed -E 's/,-warnings-as-errors\]$/]/' | sort -u >"$OUT/clang-tidy.txt" || true
  tidy_keys verify
  local rc=0
  report clang-tidy "$t0" "($(wc -l <"$OUT/tidy-files.txt") of $nfiles TUs analysed, $JOBS jobs)" || rc=$?
  # The record is rewritten only by a run without findings; the cache learns either way.
  if ((rc == 0)); then tidy_record "${MOCAP_STATIC_UPDATE:-0}"; else tidy_record 0; fi
  return "$rc"
}

# report TOOL START_SECONDS NOTE: print $OUT/TOOL.txt with paths relative to the root and a
# count per check. Findings whose file and check are listed in tests/static/known.txt (open
# findings in code being rewritten, each with its reason) are printed as known and do not
# fail; any other finding returns 1.
report() {
  local n
  sed "s|^$ROOT/||" "$OUT/$1.txt" >"$OUT/$1.rel"
  python3 - "$KNOWN" "$OUT/$1.rel" "$OUT/$1.new" <<'PY'
import re, sys
known = set()
for line in open(sys.argv[1]):
    line = line.split("#", 1)[0].split()
    if len(line) >= 2:
        known.add((line[0], line[1]))
with open(sys.argv[3], "w") as new:
    for f in open(sys.argv[2]):
        m = re.match(r"([^:]+):\d+:\d+: .*\[([^\]]+)\]$", f.strip())
        if m and (m.group(1), m.group(2)) in known:
            print("known: " + f.strip())
        else:
            new.write(f)
PY
  n=$(wc -l <"$OUT/$1.new")
  say "$1: $n new finding(s), $(($(wc -l <"$OUT/$1.rel") - n)) known, in $((SECONDS - $2)) s $3"
  if ((n > 0)); then
    cat "$OUT/$1.new"
    grep -oE '\[[^]]+\]$' "$OUT/$1.new" | sort | uniq -c | sort -rn | sed 's/^/  /'
    return 1
  fi
}

run_cppcheck() {
  if ! command -v cppcheck >/dev/null; then say "cppcheck not found (Debian package cppcheck)"; return 2; fi
  local t0=$SECONDS
  mkdir -p "$OUT/cppcheck-build"
  # warning, performance, portability: bug classes; style is left out (taste, and clang-tidy
  # covers its useful part). Third-party headers are parsed for types but not reported.
  cppcheck --project="$OUT/compile_commands.json" --cppcheck-build-dir="$OUT/cppcheck-build" \
    -j "$JOBS" --quiet --enable=warning,performance,portability --inline-suppr \
    --library=posix --suppressions-list="$SUPP" --suppress='*:/usr/*' \
    --template='{file}:{line}:{column}: {severity}: {message} [{id}]' \
    2>"$OUT/cppcheck.log" >/dev/null || true
  grep -E '^[^ ]+:[0-9]+:[0-9]+: [a-z]+: .*\[[^]]+\]$' "$OUT/cppcheck.log" \
    | sort -u >"$OUT/cppcheck.txt" || true
  report cppcheck "$t0" ""
}

for tool in $TOOLS; do
  rc=0
  case "$tool" in
    clang-tidy) run_tidy || rc=$? ;;
    cppcheck) run_cppcheck || rc=$? ;;
    *) say "unknown tool $tool"; rc=2 ;;
  esac
  if ((rc > status)); then status=$rc; fi
done
if ((status == 0)); then say "clean"; fi
exit "$status"
