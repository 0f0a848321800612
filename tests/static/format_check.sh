#!/usr/bin/env bash
# format_check.sh — fails when any tracked C/C++ file differs from what clang-format-14 makes
# of it with the repository's .clang-format (docs/style.md, "Layout"). Prints each file that
# differs and the command that fixes it.
#
#   tests/static/format_check.sh            check every tracked *.c *.h *.cpp *.hpp *.cc
#   tests/static/format_check.sh --fix      reformat them in place
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
cd "$ROOT"
fmt="$(command -v clang-format-14 || true)"
if [[ -z "$fmt" ]]; then
  echo "format_check: clang-format-14 not found (Debian package clang-format-14, in setup.sh)"
  exit 2
fi
# Tracked files when this is a git checkout, every source file otherwise (a source tarball).
if git rev-parse --is-inside-work-tree >/dev/null 2>&1; then
  mapfile -t files < <(git ls-files -- '*.c' '*.h' '*.cpp' '*.hpp' '*.cc')
else
  mapfile -t files < <(find server clients firmware tests -type f \( -name '*.c' -o -name '*.h' -o -name '*.cpp' -o -name '*.hpp' -o -name '*.cc' \) -not -path '*/node_modules/*')
fi
if [[ "${1:-}" == "--fix" ]]; then
  "$fmt" -i "${files[@]}"
  exit 0
fi
# One clang-format process for every file (one per file cost minutes on a loaded machine);
# --Werror makes each difference an error line that names its file.
mapfile -t present < <(for f in "${files[@]}"; do [[ -f "$f" ]] && echo "$f"; done)  # skip deleted, uncommitted
mapfile -t bad < <("$fmt" --dry-run --Werror "${present[@]}" 2>&1 | sed -n 's/^\(.*\):[0-9]*:[0-9]*: error: code should be clang-formatted.*/\1/p' | sort -u)
if ((${#bad[@]})); then
  printf 'format_check: %s differs from clang-format-14\n' "${bad[@]}"
  echo "format_check: ${#bad[@]} of ${#files[@]} files; fix with tests/static/format_check.sh --fix"
  exit 1
fi
echo "format_check: ${#files[@]} files formatted"
