#!/usr/bin/env bash
# benches/web/run.sh [OUTDIR]: `vtz web` archives (vtz at pixel fractions 1/4, 1/10, 1/20;
# Terrarium PNG, Terrarium WebP from the Rust encoder, Terrain-RGB PNG, f32) of Kauai (SRTM3,
# 512² and 256² tiles) and the full SRTM1 tile N45E013 (512²), z0 to the default max zoom;
# libwebp lossless and LERC2 re-encodings (bench.py); decode times in headless Chromium
# (decode.mjs) and in Node (node_decode.mjs); the tables in benches/web/run_<date>.md/.csv.
# Needs: target/ci/vtz, web/dist/vtz.wasm, cwebp (Debian webp), /work/peers-venv (pylerc),
# /usr/bin/python3 with GDAL, /usr/bin/chromium, `npm ci --prefix benches/web`.
# VTZ_WEB_SKIP_SIZES=1 reuses OUTDIR's archives; VTZ_WEB_PASSES (default 5) decode passes.
# The commit recorded is HEAD at the start; target/ci/vtz should be built from it.
set -euo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
ROOT=$(cd "$HERE/../.." && pwd)
OUT=${1:-/tmp/vtz-web-bench}
VTZ=${VTZ:-$ROOT/target/ci/vtz}
PY=${PEERS_PY:-/work/peers-venv/bin/python}
SRTM1_PNG=${SRTM1_PNG:-/work/shared/corpus/extra/srtm1_N45E013_full.png}
DATE=$(date -u +%F)
mkdir -p "$OUT"
[ -d "$HERE/node_modules/lerc" ] || npm ci --prefix "$HERE" --no-audit --no-fund

if [ -z "${VTZ_WEB_SKIP_SIZES:-}" ]; then
  git -C "$ROOT" rev-parse --short HEAD >"$OUT/commit.txt"
  # The SRTM1 PNG as a georeferenced GeoTIFF: metres = code - 32768, code 0 = nodata,
  # pixel-is-area over 45..46N 13..14E.
  /usr/bin/python3 - "$SRTM1_PNG" "$OUT/srtm1_N45E013.tif" <<'PY'
import sys, numpy as np
from osgeo import gdal, osr
a = gdal.Open(sys.argv[1]).ReadAsArray().astype(np.int32)
h = np.where(a == 0, -32768, a - 32768).astype(np.int16)
d = gdal.GetDriverByName('GTiff').Create(sys.argv[2], a.shape[1], a.shape[0], 1, gdal.GDT_Int16)
d.SetGeoTransform([13, 1 / a.shape[1], 0, 46, 0, -1 / a.shape[0]])
s = osr.SpatialReference(); s.ImportFromEPSG(4326); d.SetProjection(s.ExportToWkt())
b = d.GetRasterBand(1); b.SetNoDataValue(-32768); b.WriteArray(h); d = None
PY
  sets=("kauai512 $ROOT/corpus/srtm3_N22W160_kauai.hgt 512"
        "kauai256 $ROOT/corpus/srtm3_N22W160_kauai.hgt 256"
        "srtm1_512 $OUT/srtm1_N45E013.tif 512")
  for s in "${sets[@]}"; do
    read -r name in ts <<<"$s"
    for f in 0.25 0.1 0.05; do
      "$VTZ" web "$in" -o "$OUT/$name.vtz-$f.pmtiles" --tile-size "$ts" --pixel-fraction "$f" -f -q --json >"$OUT/$name.vtz-$f.json"
    done
    for fmt in terrarium-png terrarium-webp mapbox-png f32; do
      "$VTZ" web "$in" -o "$OUT/$name.$fmt.pmtiles" --tile-size "$ts" --format "$fmt" -f -q --json >"$OUT/$name.$fmt.json"
    done
  done
  "$PY" "$HERE/bench.py" "$OUT" kauai512 kauai256 srtm1_512
fi
# A snapshot of the wasm, so that a rebuild during the run changes nothing.
cp "${VTZ_WASM:-$ROOT/web/dist/vtz.wasm}" "$OUT/vtz.wasm"
export VTZ_WASM="$OUT/vtz.wasm"
if command -v wasm-dis >/dev/null; then wasm-dis "$VTZ_WASM" 2>/dev/null | grep -c 'v128\|i8x16\|i16x8\|i32x4' >"$OUT/vtz.wasm.simd" || true; fi
node "$HERE/node_decode.mjs" "$OUT" >"$OUT/node_decode.json"
node "$HERE/decode.mjs" "$OUT" >"$OUT/decode.json"
"$PY" "$HERE/native.py" "$OUT" >"$OUT/native.json"
"$PY" "$HERE/report.py" "$OUT" "$HERE/run_$DATE"
echo "wrote $HERE/run_$DATE.md and .csv"
