#!/usr/bin/env bash
# Fails when a tracked C++ file differs from .clang-format's style, listing the files (CI runs it through
# `make test`), and when a call draws twice from a random engine in its arguments (scripts/check-draw-order.py).
# `scripts/check-format.sh --fix` rewrites the format in place instead.
set -euo pipefail
cd "$(dirname "$0")/.."
command -v clang-format >/dev/null || { echo "check-format: clang-format is missing (scripts/install-deps.sh installs it)" >&2; exit 1; }
mapfile -t files < <(git ls-files '*.cc' '*.h' '*.cpp' '*.hpp')
[[ ${#files[@]} -eq 0 ]] && exit 0
if [[ "${1:-}" == "--fix" ]]; then
  printf '%s\0' "${files[@]}" | xargs -0 -n 50 -P "$(nproc)" clang-format -i
  exit 0
fi
# Batches of files per clang-format process (one process per file cost minutes in CI); a file that differs is named
# in its batch's "FILE:LINE:COL: error: code should be clang-formatted" lines.
mapfile -t bad < <(printf '%s\0' "${files[@]}" |
  xargs -0 -n 50 -P "$(nproc)" clang-format --dry-run --Werror 2>&1 >/dev/null |
  sed -nE 's/^([^:]+):[0-9]+:[0-9]+: error: code should be clang-formatted.*/\1/p' | sort -u || true)
if [[ ${#bad[@]} -gt 0 ]]; then
  echo "check-format: ${#bad[@]} file(s) differ from .clang-format (run scripts/check-format.sh --fix):" >&2
  printf '  %s\n' "${bad[@]}" >&2
  exit 1
fi
echo "check-format: ${#files[@]} files follow .clang-format"
# Random draws in a defined order (docs/architecture.md): the sanitizer build's compiler must see the product's noise.
scripts/check-draw-order.py "${files[@]}"
