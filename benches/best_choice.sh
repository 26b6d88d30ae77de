#!/usr/bin/env bash
# Does `--method best` (a trial on sample tiles, then full encodes of the shortlist) write
# the same file as the exhaustive choice (every method encoded in full, the smallest kept)?
# For each raster × bound: encode with every method as sections (the primary is the
# smallest: the exhaustive choice), encode with `best`, and with the exhaustive winner
# alone; compare the bytes and the times (best / winner alone: the issue-26 target is
# ≤ 1.2), and list what `best` encoded in full. Prints a markdown table.
#
#   benches/best_choice.sh [--bounds 0.1%,1%,10%] RASTER…      (needs target/release/vtz)
set -euo pipefail
VTZ=${VTZ:-target/release/vtz}
bounds="0.1%,1%,10%"
if [ "${1:-}" = "--bounds" ]; then bounds=$2; shift 2; fi
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
now() { date +%s.%N; }
echo "| raster | bound | exhaustive: method, bytes, s | best: method, bytes, s | winner alone, s | best / alone | best encoded in full | same file |"
echo "|---|---|---|---|--:|--:|---|---|"
for f in "$@"; do
  for b in ${bounds//,/ }; do
    t0=$(now)
    "$VTZ" encode "$f" -o "$tmp/all.vtz" --max-error "$b" --method sibson,grid,haar,fis,residual -q --force
    t1=$(now)
    enc=$("$VTZ" encode "$f" -o "$tmp/best.vtz" --max-error "$b" -q --force --json |
      python3 -c 'import json,sys; print(",".join(json.load(sys.stdin)["encoded"]))')
    t2=$(now)
    win=$("$VTZ" info "$tmp/all.vtz" --json | python3 -c 'import json,sys; j=json.load(sys.stdin); s=[s for s in j["sections"] if s["primary"]][0]; print(s["type"], s["bytes"])')
    got=$("$VTZ" info "$tmp/best.vtz" --json | python3 -c 'import json,sys; j=json.load(sys.stdin); s=[s for s in j["sections"] if s["primary"]][0]; print(s["type"], s["bytes"])')
    m=${win%% *}; [ "$m" = sites ] && m=sibson   # the sites section is the sibson method's
    t2b=$(now)
    "$VTZ" encode "$f" -o "$tmp/win.vtz" --max-error "$b" --method "$m" -q --force
    t3=$(now)
    same=no; cmp -s "$tmp/win.vtz" "$tmp/best.vtz" && same=yes
    printf '| %s | %s | %s, %.2f | %s, %.2f | %.2f | %.2f | %s | %s |\n' "$(basename "$f")" "$b" "$win" \
      "$(echo "$t1 - $t0" | bc)" "$got" "$(echo "$t2 - $t1" | bc)" "$(echo "$t3 - $t2b" | bc)" \
      "$(echo "($t2 - $t1) / ($t3 - $t2b)" | bc -l)" "$enc" "$same"
  done
done
