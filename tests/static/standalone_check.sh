#!/usr/bin/env bash
# standalone_check.sh — fails when a tracked file refers to something outside the repository
# (docs/style.md, "Stands alone"): an absolute path into the machine's work area, a relative
# path that climbs into a sibling "shared" directory, a "house style" citation that does not
# name docs/style.md, or a design.md that is not docs/design.md (a Markdown link next to it,
# [..](design.md#..), is allowed: GitHub resolves it inside docs/). Prints every offending line.
#
#   tests/static/standalone_check.sh [ROOT]      check ROOT (default: this checkout)
#   tests/static/standalone_check.sh --self-test plant each kind of reference in a scratch
#                                                tree and require the check to catch it
set -euo pipefail
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
SELF="tests/static/standalone_check.sh"  # the patterns below would match themselves

# The patterns are assembled from pieces so that this file does not match them.
W="/wo""rk/"
SH="\.\./sha""red"
HS="house"" style"
DM="design"'\.md'

check() {
  local root="$1" files=() bad=0
  cd "$root"
  if git rev-parse --is-inside-work-tree >/dev/null 2>&1 && [[ "$(git rev-parse --show-toplevel)" == "$root" ]]; then
    mapfile -t files < <(git ls-files)
  else
    mapfile -t files < <(find . -type f -not -path './.git/*' -not -path '*/node_modules/*' -not -path './build*' | sed 's|^\./||')
  fi
  local list=()
  for f in "${files[@]}"; do
    [[ -f "$f" && "$f" != "$SELF" ]] && list+=("$f")
  done
  ((${#list[@]})) || { echo "standalone_check: no files under $root"; return 2; }
  # -I skips binary files; -H always prints the file name.
  local out
  out="$(printf '%s\0' "${list[@]}" | xargs -0 grep -nIHE -e "$W" -e "$SH" || true)"
  if [[ -n "$out" ]]; then
    echo "$out" | sed 's/^/standalone_check: path outside the repository: /'
    bad=1
  fi
  out="$(printf '%s\0' "${list[@]}" | xargs -0 grep -nIHi -e "$HS" | grep -v 'docs/style\.md' |
    grep -v '^docs/style\.md:[0-9]*:# House style$' || true)"
  if [[ -n "$out" ]]; then
    echo "$out" | sed 's/^/standalone_check: cite docs\/style.md and the rule by name: /'
    bad=1
  fi
  out="$(printf '%s\0' "${list[@]}" | xargs -0 grep -nIHP "(?<!docs/)(?<!\]\()(?<!\[)(?<![\w/.-])$DM" || true)"
  if [[ -n "$out" ]]; then
    echo "$out" | sed 's/^/standalone_check: write docs\/design.md and the section: /'
    bad=1
  fi
  if ((bad)); then
    echo "standalone_check: the repository must not refer to files outside it (docs/style.md, \"Stands alone\")"
    return 1
  fi
  echo "standalone_check: ${#list[@]} files, no reference outside the repository"
}

self_test() {
  local tmp rc
  tmp="$(mktemp -d /tmp/standalone-check.XXXXXX)"
  trap 'rm -rf "$tmp"' RETURN
  mkdir -p "$tmp/docs" "$tmp/src"
  # Allowed forms: a clean tree passes.
  printf '%s\n' "// see docs/design.md, \"Errata: CSMO\" and docs/style.md, \"Inject time\"" \
    "// ${HS} (docs/style.md, \"Layout\")" >"$tmp/src/ok.hpp"
  printf '%s\n' "See [docs/design.md, \"Error metrics\"](design.md#error-metrics)." \
    "[design.md](design.md); mydesign.md and old_design.md are other files." >"$tmp/docs/ok.md"
  if ! (check "$tmp") >/dev/null; then
    echo "self-test: a clean tree failed"
    (check "$tmp") || true
    return 1
  fi
  # Each kind of reference alone must fail and be named.
  local -a cases=(
    "// data in ${W}shared/data/motion"
    "CLIP=\$HERE/../../${SH//\\/}/data/clip.bvh"
    "// Units (${HS} rule 4)"
    "// Convention (design.md): w first"
    "the definitions of design.md apply"
  )
  for c in "${cases[@]}"; do
    printf '%s\n' "$c" >"$tmp/src/bad.cpp"
    set +e
    out="$(check "$tmp" 2>&1)"
    rc=$?
    set -e
    if [[ $rc -ne 1 || "$out" != *"src/bad.cpp:1:"* ]]; then
      echo "self-test: not caught (exit $rc): $c"
      echo "$out"
      return 1
    fi
    echo "self-test: caught: $c"
  done
  rm -f "$tmp/src/bad.cpp"
  echo "self-test: ${#cases[@]} planted references caught, clean tree passes"
}

if [[ "${1:-}" == "--self-test" ]]; then
  self_test
else
  root="$(cd "${1:-$HERE/../..}" && pwd)"
  check "$root"
fi
