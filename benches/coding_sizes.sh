#!/bin/bash
# Sizes of the residual layer's codings against the default on every corpus raster:
# `vtz encode --method residual` at efforts 1 (lane coding), 2 (fast coding) and 5 (the
# default, range-coded) for lossless, 1 m and 1 % of the range; prints a Markdown table with
# per-column geometric means of the ratios (benches/README.md, "the lane coding").
#
#   benches/coding_sizes.sh [CORPUS_DIR]      (default ../shared/corpus)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
corpus=${1:-$root/../shared/corpus}
vtz=$root/target/release/vtz
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
for f in "$corpus"/*.f32; do
  n=$(basename "$f" .f32)
  for b in lossless 1 1%; do
    for e in 1 2 5; do
      args=(encode "$f" -o "$out/x.vtz" --force -q --method residual --effort "$e")
      [ "$b" != lossless ] && args+=(--max-error "$b")
      if "$vtz" "${args[@]}" 2>/dev/null; then s=$(stat -c %s "$out/x.vtz"); else s=NA; fi
      echo "$n,$b,$e,$s"
    done
  done
done > "$out/sizes.csv"
python3 - "$out/sizes.csv" <<'PY'
import csv, math, sys
rows = {}
for n, b, e, s in csv.reader(open(sys.argv[1])):
    rows.setdefault(n, {})[(b, e)] = None if s == "NA" else int(s)
bounds = ["lossless", "1", "1%"]
print("| raster | " + " | ".join(f"{b}: lane / fast / default bytes | lane ÷ default | fast ÷ default" for b in bounds) + " |")
print("|---|" + "--:|--:|--:|" * len(bounds))
logs = {b: ([], []) for b in bounds}
for n in sorted(rows):
    cells = []
    for b in bounds:
        l, f, d = (rows[n].get((b, e)) for e in "125")
        if None in (l, f, d):
            cells += ["no lattice", "", ""]
            continue
        logs[b][0].append(math.log(l / d)); logs[b][1].append(math.log(f / d))
        cells += [f"{l} / {f} / {d}", f"{l / d:.3f}", f"{f / d:.3f}"]
    print(f"| {n} | " + " | ".join(cells) + " |")
g = lambda v: math.exp(sum(v) / len(v))
print("| **geomean** | " + " | ".join(f" | **{g(logs[b][0]):.3f}** | **{g(logs[b][1]):.3f}**" for b in bounds) + " |")
PY
