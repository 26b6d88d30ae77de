#!/usr/bin/env bash
# Would a residual layer on top of a sites surface beat the residual layer alone? An
# estimate with the CLI: sites at a coarser bound B (the base), the lattice difference
# source − round(base) coded with the residual layer at bound E, against the residual layer
# alone at E. Prints one line per raster × (E, B).
# Usage: benches/sites_plus_residual.sh VTZ PYTHON_WITH_NUMPY [RASTER...]   (../shared/corpus)
set -euo pipefail
V=$1; P=$2; shift 2
C=$(cd "$(dirname "$0")/.." && pwd)/../shared/corpus
names=("$@"); [ ${#names[@]} -gt 0 ] || names=(srtm3_N44W072_white_mountains scape_crater)
t=$(mktemp -d); trap 'rm -rf "$t"' EXIT; cd "$t"
for r in "${names[@]}"; do
  for pair in "1%:4%" "1%:10%" "0.3%:3%" "3%:10%"; do
    E=${pair%%:*}; B=${pair##*:}
    "$V" encode "$C/$r.f32" --method sibson --max-error "$B" -o base.vtz -f -q
    "$V" decode base.vtz -o base.f32 -f -q
    Eabs=$("$P" - "$C/$r.f32" base.f32 "$E" <<'PY'
import numpy as np, json, sys
src = sys.argv[1]; j = json.load(open(src[:-4] + ".json"))
a = np.fromfile(src, "<f4"); b = np.fromfile("base.f32", "<f4")
(a - np.round(b)).astype("<f4").tofile("diff.f32")
jj = dict(j); jj["nodata"] = None; jj["source_dtype"] = "float32"
json.dump(jj, open("diff.json", "w"))
print((a.max() - a.min()) * float(sys.argv[3][:-1]) / 100)
PY
)
    "$V" encode diff.f32 --method residual --max-error "$Eabs" -o diff.vtz -f -q
    "$V" encode "$C/$r.f32" --method residual --max-error "$E" -o res.vtz -f -q
    s=$(stat -c %s base.vtz); d=$(stat -c %s diff.vtz)
    echo "$r E=$E base=$B sites=$s residual_on_difference=$d sum=$((s + d)) residual_alone=$(stat -c %s res.vtz)"
  done
done
