#!/usr/bin/env bash
# What each encoder choice of the residual layer gains, in bits per sample: effort 1 (one
# predictor by rule), 3 (the smaller of interpolation and the weighted scan), 5 (and
# sub-lattice bins for float output), beside the grid method (MED + 24 contexts, the
# previous generation). One CSV line per raster × bound.
# Usage: benches/residual_choices.sh VTZ [RASTER...]   (rasters of ../shared/corpus)
set -euo pipefail
V=$1; shift
C=$(cd "$(dirname "$0")/.." && pwd)/../shared/corpus
names=("$@"); [ ${#names[@]} -gt 0 ] || names=(scape_crater srtm3_N44W072_white_mountains srtm3_N22W160_kauai ned1_halfdome_yosemite ahn3_delft_dsm_50cm srtm3_N57E011_kattegat)
t=$(mktemp -d); trap 'rm -rf "$t"' EXIT
bps() { "$V" encode "$@" -o "$t/x.vtz" -f --json -q | python3 -c 'import json,sys; print("%.4f" % json.load(sys.stdin)["bits_per_sample"])'; }
echo "raster,bound,grid,residual_e1,residual_e3,residual_e5"
for r in "${names[@]}"; do
  for b in lossless 1 2 0.1% 1%; do
    if [ "$b" = lossless ]; then a=(--lossless); else a=(--max-error "$b"); fi
    g=$(bps "$C/$r.f32" "${a[@]}" --method grid)
    e1=$(bps "$C/$r.f32" "${a[@]}" --method residual --effort 1)
    e3=$(bps "$C/$r.f32" "${a[@]}" --method residual --effort 3)
    e5=$(bps "$C/$r.f32" "${a[@]}" --method residual --effort 5)
    echo "$r,$b,$g,$e1,$e3,$e5"
  done
done
