#!/usr/bin/env bash
# CI's clang-tidy gate: fails on findings that .ci/tidy-baseline.txt does not allow. The whole tree costs far more
# than CI's budget (bench/results/typed7.md), so the baseline names a commit and the findings allowed at it (a
# count per file and check, for findings not fixed yet); CI checks only the C++ sources changed since that commit
# (a header through the source beside it, else through one source that includes it). A (file, check) whose count
# exceeds the baseline's fails; a file the baseline does not list may have none.
#   scripts/tidy_ci.sh [DB]            check (DB: a build folder with a one-object-per-file compile_commands.json;
#                                      default build-tidy, configured here without building anything)
#   scripts/tidy_ci.sh --update [DB]   after a landing: check the changed files again, record what they have now
#                                      as allowed, and move the baseline to HEAD, so CI's cost stays that of one
#                                      landing's changes (`make tidy-baseline`)
# TIDY_JOBS: clang-tidy processes at once (default: every core).
set -euo pipefail
cd "$(dirname "$0")/.."
update=0
[[ "${1:-}" == "--update" ]] && { update=1; shift; }
db=${1:-build-tidy}
baseline=.ci/tidy-baseline.txt
command -v clang-tidy >/dev/null || { echo "tidy: clang-tidy is missing (apt-get install clang-tidy)" >&2; exit 1; }
base=$(awk '$1 == "base" { print $2 }' "$baseline")
git cat-file -e "$base^{commit}" 2>/dev/null ||
  { echo "tidy: the baseline's commit $base is not in this clone (fetch the history: git fetch --unshallow)" >&2; exit 1; }
# A unity build's database names its batches, not the sources: configure a per-file one (seconds; nothing built).
if [[ ! -f "$db/compile_commands.json" ]] || grep -q '/unity_[0-9]*_cxx\.cxx' "$db/compile_commands.json"; then
  db=build-tidy
  cmake -S . -B "$db" -G Ninja -DCMAKE_BUILD_TYPE=Release -DFMV3D_UNITY=OFF -DFMV3D_PCH=OFF >/dev/null
fi

# bench/results/ holds one-off analysis tools beside the figures they produced: not built, no compile database entry.
mapfile -t changed < <(git diff --name-only --diff-filter=AMR "$base" -- '*.cc' '*.h' |
  grep -v -e '^tests/fuzz/' -e '^bench/results/' | sort -u)
sources=()
for f in "${changed[@]}"; do
  if [[ "$f" == *.h ]]; then
    if [[ -f "${f%.h}.cc" ]]; then
      sources+=("${f%.h}.cc")
    else
      inc=${f#src/}
      user=$(grep -rlsF --include='*.cc' "#include \"$inc\"" src tests apps | grep -v '^tests/fuzz/' | sort | head -n 1 || true)
      [[ -n "$user" ]] && sources+=("$user")
    fi
  else
    sources+=("$f")
  fi
done
mapfile -t sources < <(printf '%s\n' "${sources[@]}" | sed '/^$/d' | sort -u)
echo "tidy: ${#changed[@]} C++ file(s) changed since $(git rev-parse --short "$base"), ${#sources[@]} source(s) to check" >&2

log=$(mktemp)
trap 'rm -f "$log"' EXIT
if [[ ${#sources[@]} -gt 0 ]]; then
  printf '%s\0' "${sources[@]}" | xargs -0 -n 1 -P "${TIDY_JOBS:-$(nproc)}" clang-tidy -p "$db" --quiet >"$log" 2>/dev/null || true
fi
# Findings in the changed files only (a header's show once per source that includes it): "file<TAB>check<TAB>line".
top=$(pwd)/
found=$(grep -E '^[^ ]+:[0-9]+:[0-9]+: (warning|error): .* \[[a-z0-9.,-]+\]$' "$log" | sed "s#^$top##" |
  sed -E 's/^([^:]+):([0-9]+:[0-9]+): (warning|error): (.*) \[([^]]+)\]$/\1\t\5\t\2: \4/' | sort -u |
  awk -F'\t' 'NR == FNR { keep[$0] = 1; next } ($1 in keep)' <(printf '%s\n' "${changed[@]}") - || true)

if [[ $update -eq 1 ]]; then
  [[ -z "$(git status --porcelain -- '*.cc' '*.h')" ]] || { echo "tidy: commit the C++ changes first" >&2; exit 1; }
  tmp=$(mktemp)
  {
    sed -n '/^#/p' "$baseline"
    echo "base $(git rev-parse HEAD)"
    # Entries of files not checked now stay; the checked files get what they have now; deleted files go.
    awk '!/^#/ && $1 != "base"' "$baseline" | awk -F'\t' 'NR == FNR { drop[$0] = 1; next } !($2 in drop)' \
      <(printf '%s\n' "${changed[@]}") - | while IFS=$'\t' read -r n f c; do [[ -f "$f" ]] && printf '%s\t%s\t%s\n' "$n" "$f" "$c"; done
    if [[ -n "$found" ]]; then
      echo "$found" | cut -f1,2 | sort | uniq -c | awk '{ printf "%s\t%s\t%s\n", $1, $2, $3 }'
    fi
  } | awk '/^#/ || /^base / { print; next } { print | "sort -t\"\t\" -k2,2 -k3,3" }' >"$tmp"
  mv "$tmp" "$baseline"
  echo "tidy: baseline moved to $(git rev-parse --short HEAD), $(awk -F'\t' '!/^#/ && !/^base / { s += $1 } END { print s + 0 }' "$baseline") finding(s) allowed"
  exit 0
fi

# Compare counts per (file, check) with the baseline's.
over=$(awk -F'\t' '
  FILENAME == ARGV[1] { if ($0 !~ /^#/ && $0 !~ /^base /) allowed[$2 "\t" $3] = $1; next }
  { n[$1 "\t" $2]++; line[$1 "\t" $2] = line[$1 "\t" $2] "\n  " $1 ":" $3 " [" $2 "]" }
  END { for (k in n) if (n[k] > allowed[k] + 0) printf "%s (%d, allowed %d)%s\n", k, n[k], allowed[k] + 0, line[k] }
' "$baseline" <(echo -n "$found"))
if [[ -n "$over" ]]; then
  echo "$over" >&2
  echo "tidy: new findings: fix them, or where one must stay, count it in $baseline and say why in the commit" >&2
  exit 1
fi
echo "tidy: ${#sources[@]} source(s) checked, no finding beyond the baseline ($(echo -n "$found" | grep -c . || true) allowed)"
