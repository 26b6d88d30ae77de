#!/usr/bin/env bash
# Rate-distortion table of vtz's methods on rasters, at max-error bounds in % of the range.
# usage: benches/rd_sites.sh [--methods sibson,grid] [--bounds 0.1,0.3,1,3,10] [--timeout S] FILE...
# Prints a Markdown table: bytes, bits/sample, RMSE and max error (also in % of the range),
# sites, encode and decode wall seconds. Every row is checked with `vtz compare`.
set -euo pipefail
methods=sibson,grid; bounds=0.1,0.3,1,3,10; tmo=600
while [ $# -gt 0 ]; do
  case "$1" in
    --methods) methods=$2; shift 2;;
    --bounds) bounds=$2; shift 2;;
    --timeout) tmo=$2; shift 2;;
    *) break;;
  esac
done
cd "$(dirname "$0")/.."
cargo build --release -q
vtz=target/release/vtz
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
echo "| raster | method | bound | bytes | bps | RMSE | max err | RMSE % | max % | sites | enc s | dec s |"
echo "|---|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|"
for f in "$@"; do
  name=$(basename "${f%.*}")
  for m in ${methods//,/ }; do
    for b in ${bounds//,/ }; do
      t0=$(date +%s.%N)
      if ! enc=$(timeout "$tmo" $vtz encode "$f" -o "$tmp/o.vtz" --max-error "$b%" --method "$m" --force --json -q 2>"$tmp/err"); then
        echo "| $name | $m | $b % | — | — | — | — | — | — | — | >$tmo | — |"; continue
      fi
      t1=$(date +%s.%N)
      $vtz decode "$tmp/o.vtz" -o "$tmp/d.f32" --force -q
      t2=$(date +%s.%N)
      cmp=$($vtz compare "$f" "$tmp/o.vtz" --json)
      python3 - "$name" "$m" "$b" "$enc" "$cmp" "$t0" "$t1" "$t2" <<'PY'
import json, sys
name, m, b, enc, cmp, t0, t1, t2 = sys.argv[1:]
e, c = json.loads(enc), json.loads(cmp)
assert c["max_error_pct"] <= float(b) + 1e-9, (name, m, b, c)
sites = e.get("sites") or "—"
print(f"| {name} | {e['method']} | {b} % | {e['bytes']} | {e['bits_per_sample']:.4f} | {c['rmse']:.3f} | {c['max_error']:.3f} "
      f"| {c['rmse_pct']:.4f} | {c['max_error_pct']:.4f} | {sites} | {float(t1)-float(t0):.2f} | {float(t2)-float(t1):.2f} |")
PY
    done
  done
done
