#!/usr/bin/env bash
# Sites (Sibson) encode/decode time beside SZ3 and LERC on the same files, bounds and core,
# in the same run: for each raster, vtz (benches/sites_speed.rs, median of RUNS) and the
# peers harness (../shared/tools/peers, best of RUNS) alternate twice (A B A B) on one core,
# and the table keeps the median of each side's two rounds.
# Usage: benches/sites_vs_peers.sh PYTHON_WITH_PEERS [RUNS] [RASTER.f32 …] > table.md
# (default rasters: White Mountains 1201², Half Dome, Istria 2400²; bounds 1 % and 10 %)
set -euo pipefail
py=$1; runs=${2:-3}; shift $(( $# >= 2 ? 2 : 1 ))
here=$(cd "$(dirname "$0")/.." && pwd)
corpus=$here/../shared/corpus
peers=$here/../shared/tools/peers/peers.py
core=${CORE:-0}
if [ $# -gt 0 ]; then files=("$@"); else
  files=("$corpus/srtm3_N44W072_white_mountains.f32" "$corpus/ned1_halfdome_yosemite.f32"
         "$corpus/srtm1_N45E013_istria_crop2400.f32")
fi
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
cd "$here"
bench=$(cargo bench --bench sites_speed --no-run 2>&1 | sed -n 's/.*(\(.*sites_speed-[0-9a-f]*\)).*/\1/p' | tail -1)
for round in 1 2; do
  for f in "${files[@]}"; do
    taskset -c "$core" "$bench" --runs "$runs" --bounds 1%,10% "$f" | tail -n +2 >> "$tmp/vtz.tsv"
    taskset -c "$core" "$py" "$peers" "$f" --codecs sz3,lerc --pct 1,10 --abs "" \
      --repeat "$runs" --csv "$tmp/p_${round}_$(basename "$f" .f32).csv" > /dev/null
  done
done
"$py" - "$tmp" <<'PY'
import csv, glob, statistics, sys
tmp = sys.argv[1]
vtz = {}
for l in open(f"{tmp}/vtz.tsv"):
    r = l.rstrip("\n").split("\t")
    vtz.setdefault((r[0], r[2]), []).append((int(r[1]), int(r[3]), float(r[4]), float(r[5])))
peer = {}
for fn in glob.glob(f"{tmp}/p_*.csv"):
    for r in csv.DictReader(open(fn)):
        if r["target"] in ("1%", "10%"):
            peer.setdefault((r["raster"], r["target"], r["codec"]), []).append(
                (int(r["bytes"]), float(r["enc_s"]), float(r["dec_s"])))
med = statistics.median
print("| raster | bound | vtz bytes | vtz enc s | vtz dec s | enc M/s | dec M/s | SZ3 enc s | SZ3 dec s | LERC enc s | LERC dec s | enc ÷ SZ3 | dec ÷ SZ3 | dec ÷ LERC |")
print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
for (name, b), rows in vtz.items():
    n = rows[0][0]
    e, d = med(x[2] for x in rows), med(x[3] for x in rows)
    s = peer.get((name, b, "sz3"), [])
    lc = peer.get((name, b, "lerc"), [])
    se, sd = (med(x[1] for x in s), med(x[2] for x in s)) if s else (float("nan"),) * 2
    le, ld = (med(x[1] for x in lc), med(x[2] for x in lc)) if lc else (float("nan"),) * 2
    print(f"| {name} | {b} | {rows[0][1]} | {e:.3f} | {d:.3f} | {n/e/1e6:.2f} | {n/d/1e6:.2f} | "
          f"{se:.4f} | {sd:.4f} | {le:.4f} | {ld:.4f} | {e/se:.0f}× | {d/sd:.0f}× | {d/ld:.0f}× |")
PY
