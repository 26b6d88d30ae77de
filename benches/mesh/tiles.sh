#!/usr/bin/env bash
# vtz tiles on geographic rasters: wall time, peak memory, tiles, bytes (plain and gzip),
# the per-level bound and measured error. Usage: benches/mesh/tiles.sh VTZ_BINARY FILE... 
# (each FILE at 1 % of its range and at 5 m; SRTM1 1° tiles: unzip
# ../shared/corpus/extra/N37E051.SRTMGL1.hgt.zip first).
set -euo pipefail
vtz="$1"; shift
out="$(mktemp -d)"
for f in "$@"; do
  for e in 1% 5; do
    for gz in "" "--gzip"; do
      /usr/bin/time -f "%e s wall, %M KB peak" -o "$out/time" \
        "$vtz" tiles "$f" -o "$out/t" --max-error "$e" $gz --json -f -q > "$out/j.json"
      python3 - "$f" "$e" "${gz:-plain}" "$out/j.json" "$out/time" <<'PY'
import json, sys
f, e, gz, j, t = sys.argv[1:]
d = json.load(open(j))
fine = d["levels"][-1]
print(f"| {f.split('/')[-1]} | {e} | {gz} | {len(d['levels']) - 1} | {d['tiles']} | {d['bytes']} | "
      f"{sum(l['vertices'] for l in d['levels'])} | {fine['max_error']:.3f} ≤ {fine['target']:.3f} | "
      f"{fine['rmse']:.3f} | {open(t).read().strip()} |")
if gz == "plain" and e == "1%":
    print("|  | zoom | bound | sites (prefix) | vertices | added | max error | RMSE | bytes |", file=sys.stderr)
    for l in d["levels"]:
        print(f"|  | {l['zoom']} | {l['target']:.2f} | {l['sites']} | {l['vertices']} | {l['added']} | {l['max_error']:.2f} | {l['rmse']:.2f} | {l['bytes']} |", file=sys.stderr)
PY
    done
  done
done
rm -rf "$out"
