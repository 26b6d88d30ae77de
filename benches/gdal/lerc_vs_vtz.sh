#!/usr/bin/env bash
# gdal_translate -of VTZ against GDAL's own LERC (GeoTIFF COMPRESS=LERC and LERC_ZSTD) on the
# same inputs at MAX_Z_ERROR=1 (vtz at the default effort and at EFFORT=1): bytes, write and read times (median of REPEATS, wall
# seconds, whole processes), and the max error each file reads back with (numpy, over the
# source's valid samples). Needs the plugin: capi/build-gdal-plugin.sh.
#
#   benches/gdal/lerc_vs_vtz.sh WORK_DIR [REPEATS]      (prints a Markdown table)
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
work="$1"; reps="${2:-3}"
mkdir -p "$work"
export GDAL_DRIVER_PATH="$root/target/gdal-plugin"
vtz="$root/target/release/vtz"
shared="$root/../shared/corpus"
[ -f "$work/srtm1.tif" ] || "$vtz" convert "$shared/extra/srtm1_N45E013_full.png" "$work/srtm1.tif" \
  --png-offset -32768 --png-nodata 0 -q
[ -f "$work/kauai.tif" ] || "$vtz" convert "$root/corpus/srtm3_N22W160_kauai.hgt" "$work/kauai.tif" -q
[ -f "$work/delft.tif" ] || "$vtz" convert "$shared/ahn3_delft_dtm_50cm.f32" "$work/delft.tif" -q

median() { sort -g | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}'; }
timed() { # prints wall seconds of "$@", median of $reps runs
  for _ in $(seq "$reps"); do
    s=$(date +%s.%N); "$@" >/dev/null 2>&1; e=$(date +%s.%N)
    echo "$e - $s" | bc
  done | median
}
maxerr() { # source, decoded: max |a - b| over the source's valid samples
  /usr/bin/python3 - "$1" "$2" <<'PY'
import sys, numpy as np
from osgeo import gdal
a = gdal.Open(sys.argv[1]); b = gdal.Open(sys.argv[2])
x = a.GetRasterBand(1).ReadAsArray().astype(np.float64)
y = b.GetRasterBand(1).ReadAsArray().astype(np.float64)
nd = a.GetRasterBand(1).GetNoDataValue()
valid = ~np.isnan(x) if nd is None else (x != nd) & ~np.isnan(x)
print(f"{np.max(np.abs(x[valid] - y[valid])):.4g}")
PY
}

echo "| input | codec | bytes | bytes / LERC | write s | read s (to uncompressed GeoTIFF) | max error |"
echo "|---|---|--:|--:|--:|--:|--:|"
for name in srtm1 kauai delft; do
  src="$work/$name.tif"
  lerc_bytes=""
  for codec in LERC LERC_ZSTD VTZ VTZ_EFFORT1; do
    if [ "$codec" = VTZ ]; then
      out="$work/$name.vtz"; args=(-of VTZ -co MAX_Z_ERROR=1)
    elif [ "$codec" = VTZ_EFFORT1 ]; then
      out="$work/$name.e1.vtz"; args=(-of VTZ -co MAX_Z_ERROR=1 -co EFFORT=1)
    else
      out="$work/$name.$codec.tif"; args=(-of GTiff -co TILED=YES -co COMPRESS="$codec" -co MAX_Z_ERROR=1)
    fi
    w=$(timed gdal_translate -q "${args[@]}" "$src" "$out")
    r=$(timed gdal_translate -q -of GTiff "$out" "$work/$name.read.tif")
    bytes=$(stat -c %s "$out")
    [ "$codec" = LERC ] && lerc_bytes=$bytes
    err=$(maxerr "$src" "$work/$name.read.tif")
    ratio=$(echo "scale=4; $bytes / $lerc_bytes" | bc)
    printf '| %s | %s | %s | %.3f | %.3f | %.3f | %s |\n' "$name" "$codec" "$bytes" "$ratio" "$w" "$r" "$err"
  done
done
