#!/usr/bin/env bash
# `--method best` against the method it writes, encoded alone: CPU seconds (user + sys) of
# whole processes, RUNS paired runs (best, alone, best, alone, …), medians. Issue 37's
# target: best ≤ 1.2× its choice's time. Prints a Markdown table.
#
#   benches/best_time.sh [--bounds 1,1%,10%] [--runs 3] RASTER…     (VTZ: the binary)
set -euo pipefail
VTZ=${VTZ:-target/release/vtz}
bounds="1,1%,10%"; runs=3
while [ $# -gt 0 ]; do
  case $1 in
    --bounds) bounds=$2; shift 2 ;;
    --runs) runs=$2; shift 2 ;;
    *) break ;;
  esac
done
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
cpu() { /usr/bin/time -f "%U %S" -o "$tmp/t" "$@" >/dev/null; awk '{print $1 + $2}' "$tmp/t"; }
median() { sort -g | awk '{a[NR]=$1} END {print (NR % 2) ? a[(NR+1)/2] : (a[NR/2] + a[NR/2+1]) / 2}'; }
echo "| raster | bound | best writes | bytes | encoded in full | best cpu s | alone cpu s | best / alone |"
echo "|---|---|---|--:|---|--:|--:|--:|"
for f in "$@"; do
  for b in ${bounds//,/ }; do
    j=$("$VTZ" encode "$f" -o "$tmp/b.vtz" --max-error "$b" -f -q --json)
    m=$(echo "$j" | python3 -c 'import json,sys; print(json.load(sys.stdin)["method"])')
    enc=$(echo "$j" | python3 -c 'import json,sys; print(",".join(json.load(sys.stdin)["encoded"]))')
    bytes=$(echo "$j" | python3 -c 'import json,sys; print(json.load(sys.stdin)["bytes"])')
    : > "$tmp/best"; : > "$tmp/alone"
    for _ in $(seq "$runs"); do
      cpu "$VTZ" encode "$f" -o "$tmp/b.vtz" --max-error "$b" -f -q >> "$tmp/best"
      cpu "$VTZ" encode "$f" -o "$tmp/a.vtz" --max-error "$b" --method "$m" -f -q >> "$tmp/alone"
    done
    tb=$(median < "$tmp/best"); ta=$(median < "$tmp/alone")
    printf '| %s | %s | %s | %s | %s | %.2f | %.2f | %.2f |\n' "$(basename "$f" .f32)" "$b" "$m" "$bytes" "$enc" \
      "$tb" "$ta" "$(echo "$tb / ($ta + 0.000001)" | bc -l)"
  done
done
