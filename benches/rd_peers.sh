#!/usr/bin/env bash
# vtz best on every raster of ../shared/corpus at every bound of the peers table (lossless,
# abs 0.5/1/2/5, 0.01 … 10 % of the range), each decode checked independently with
# ../shared/tools/rastercmp.py. Writes CSV on stdout:
#   raster,target,bound,bytes,bps,method,max_err,check
# Usage: benches/rd_peers.sh VTZ_BINARY PYTHON_WITH_NUMPY [RASTER...] > vtz21.csv
# BOUNDS="3% 10%" benches/rd_peers.sh … measures only those bounds.
# (benches/rd_peers.py merges it with the peers harness CSV into the table in README.md.)
set -euo pipefail
vtz=$1; py=$2; shift 2
here=$(cd "$(dirname "$0")/.." && pwd)
corpus=$here/../shared/corpus
cmp=$here/../shared/tools/rastercmp.py
if [ $# -gt 0 ]; then names=("$@"); else
  names=(); for f in "$corpus"/*.f32; do names+=("$(basename "$f" .f32)"); done
fi
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
echo "raster,target,bound,bytes,bps,method,max_err,check"
for n in "${names[@]}"; do
  src=$corpus/$n.f32
  for t in ${BOUNDS:-lossless 0.5 1 2 5 0.01% 0.03% 0.1% 0.3% 1% 3% 10%}; do
    if [ "$t" = lossless ]; then a=(--lossless); else a=(--max-error "$t"); fi
    j=$("$vtz" encode "$src" "${a[@]}" -o "$tmp/x.vtz" -f --json -q)
    bytes=$(echo "$j" | "$py" -c 'import json,sys; print(json.load(sys.stdin)["bytes"])')
    method=$(echo "$j" | "$py" -c 'import json,sys; print(json.load(sys.stdin)["method"])')
    bound=$("$py" - "$src" "$t" <<'PY'
import json, sys
src, t = sys.argv[1], sys.argv[2]
j = json.load(open(src[:-4] + ".json"))
if t == "lossless": print(0)
elif t.endswith("%"):
    import numpy as np
    a = np.fromfile(src, "<f4").astype(np.float64)
    nd = j.get("nodata")
    v = a[np.isfinite(a) & ((a != nd) if nd is not None else True)]
    print(float((v.max() - v.min()) * float(t[:-1]) / 100))
else: print(t)
PY
)
    "$vtz" decode "$tmp/x.vtz" -o "$tmp/x.f32" -f -q
    if out=$("$py" "$cmp" "$src" "$tmp/x.f32" --bound "$bound" --vtz "$tmp/x.vtz"); then ok=yes; else ok=NO; fi
    me=$(echo "$out" | awk '{print $2}')
    bps=$(echo "$out" | awk '{print $NF}')
    echo "$n,$t,$bound,$bytes,$bps,$method,$me,$ok"
  done
done
