#!/usr/bin/env bash
# clang-tidy (.clang-tidy) on the C++ sources changed since BASE (default: the merge base with main, else HEAD~1),
# using BUILD's compile_commands.json; fails on any finding in them. The whole tree takes ~75 CPU-minutes (a
# front-end pass per translation unit), so checks run on what a change touches: `make tidy BASE=<ref>`.
#   scripts/tidy.sh [BASE] [BUILD]      e.g. scripts/tidy.sh main build
set -euo pipefail
cd "$(dirname "$0")/.."
base=${1:-}
build=${2:-build}
command -v clang-tidy >/dev/null || { echo "tidy: clang-tidy is missing (apt-get install clang-tidy)" >&2; exit 1; }
[[ -f "$build/compile_commands.json" ]] || { echo "tidy: $build/compile_commands.json is missing (configure $build first)" >&2; exit 1; }
if [[ -z "$base" ]]; then
  base=$(git merge-base HEAD main 2>/dev/null || true)
  [[ -z "$base" || "$base" == "$(git rev-parse HEAD)" ]] && base=$(git rev-parse --verify -q HEAD~1 || true)
fi
[[ -n "$base" ]] || { echo "tidy: no base to compare with (give one: scripts/tidy.sh <ref>)" >&2; exit 1; }
# Sources changed since base, plus the sources beside changed headers (a header is checked through its .cc).
mapfile -t changed < <(git diff --name-only --diff-filter=AM "$base" -- '*.cc' '*.h' | sort -u)
files=()
for f in "${changed[@]}"; do
  case "$f" in
    tests/fuzz/*) continue ;;  # built by clang with libFuzzer flags, not in the compile database
    *.h) [[ -f "${f%.h}.cc" ]] && files+=("${f%.h}.cc") ;;
    *) files+=("$f") ;;
  esac
done
mapfile -t files < <(printf '%s\n' "${files[@]}" | sort -u | sed '/^$/d')
if [[ ${#files[@]} -eq 0 ]]; then echo "tidy: no C++ source changed since $base"; exit 0; fi
echo "tidy: ${#files[@]} file(s) changed since $(git rev-parse --short "$base")" >&2
log=$(mktemp)
trap 'rm -f "$log"' EXIT
printf '%s\0' "${files[@]}" | xargs -0 -n 1 -P "$(nproc)" clang-tidy -p "$build" --quiet >"$log" 2>/dev/null || true
# Only findings in the changed files count (a header's findings show once per file that includes it).
pattern=$(printf '%s\n' "${changed[@]}" | sed 's/[.[\*^$]/\\&/g; s#^#/#; s#$#:[0-9]+:[0-9]+: (warning|error): #' | paste -sd'|')
findings=$(grep -E "$pattern" "$log" | sort -u || true)
if [[ -n "$findings" ]]; then
  echo "$findings" >&2
  echo "tidy: $(echo "$findings" | wc -l) finding(s) in the changed files" >&2
  exit 1
fi
echo "tidy: ${#files[@]} file(s) clean"
