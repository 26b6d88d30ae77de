#!/bin/sh
# Make pairs X.vtz + X.f32 (+ X.json) for web/test/cases.test.js: rasters encoded and
# decoded by the native CLI, which the wasm decoder must reproduce bit for bit
# (VTZ_WEB_CASES=OUTDIR node --test web/test/).
#   web/test/make_cases.sh VTZ_BIN OUTDIR
# Sources: crops of corpus/srtm3_N22W160_kauai.hgt (256², 512², one with a nodata hole), a
# random float raster, and the full 1201² tile; efforts 2 (fast coding), 5 (lanes, the
# default) and 6 (range-coded); untiled and tiled; the grid, haar and fis methods once.
set -eu
[ $# -eq 2 ] || { echo "usage: $0 VTZ_BIN OUTDIR" >&2; exit 2; }
vtz=$1
out=$2
root=$(cd "$(dirname "$0")/../.." && pwd)
mkdir -p "$out"
src="$out/src"
mkdir -p "$src"

"$vtz" encode -q -f --lossless --tile 0 "$root/corpus/srtm3_N22W160_kauai.hgt" -o "$src/kauai.vtz"
"$vtz" decode -q -f "$src/kauai.vtz" -o "$src/kauai.f32"
"$vtz" decode -q -f "$src/kauai.vtz" --window 400,945,256,256 -o "$src/k256.f32"
"$vtz" decode -q -f "$src/kauai.vtz" --window 330,689,512,512 -o "$src/k512.f32"
"$vtz" decode -q -f "$src/kauai.vtz" --window 500,900,256,256 -o "$src/k256nd.f32"
# A nodata disc in k256nd and a random float raster (both need a nodata value in the json).
node - "$src" <<'JS'
const fs = require('fs');
const dir = process.argv[2];
const nd = (name) => {
  const meta = JSON.parse(fs.readFileSync(`${dir}/${name}.json`, 'utf8'));
  meta.nodata = -32768;
  return meta;
};
const meta = nd('k256nd');
const b = fs.readFileSync(`${dir}/k256nd.f32`);
const v = new Float32Array(b.buffer, b.byteOffset, b.length / 4);
for (let y = 0; y < 256; y++)
  for (let x = 0; x < 256; x++) if ((x - 90) ** 2 + (y - 140) ** 2 < 50 ** 2 || x > 240) v[y * 256 + x] = -32768;
fs.writeFileSync(`${dir}/k256nd.f32`, b);
fs.writeFileSync(`${dir}/k256nd.json`, JSON.stringify(meta));
let s = 12345;
const rnd = () => ((s = (s * 1103515245 + 12345) >>> 0) / 2 ** 32);
const [w, h] = [300, 200];
const r = new Float32Array(w * h);
for (let y = 0; y < h; y++)
  for (let x = 0; x < w; x++) {
    const up = y ? r[(y - 1) * w + x] : 100, left = x ? r[y * w + x - 1] : up;
    r[y * w + x] = Math.fround((up + left) / 2 + (rnd() - 0.5) * 7.3);
  }
for (let i = 0; i < 400; i++) r[Math.floor(rnd() * w * h)] = -32768;
fs.writeFileSync(`${dir}/rand.f32`, Buffer.from(r.buffer));
fs.writeFileSync(`${dir}/rand.json`, JSON.stringify({ width: w, height: h, nodata: -32768 }));
JS

enc() { # NAME SOURCE ENCODE-ARGS...
    name=$1
    in=$2
    shift 2
    "$vtz" encode -q -f "$in" -o "$out/$name.vtz" "$@"
    "$vtz" decode -q -f --threads 1 "$out/$name.vtz" -o "$out/$name.f32"
}
for s in k256 k512 k256nd rand; do
    for e in 2 5 6; do
        err=1
        case $s in rand) err=0.37 ;; k512) err=2.5 ;; esac
        enc "${s}_e${e}" "$src/$s.f32" --max-error $err --effort $e --tile 0
        enc "${s}_e${e}_t128" "$src/$s.f32" --max-error $err --effort $e --tile 128
    done
done
enc k256_lossless "$src/k256.f32" --lossless --tile 0
enc k256_grid "$src/k256.f32" --max-error 1 --method grid --tile 0
enc k256_haar "$src/k256.f32" --max-error 1 --method haar --tile 0
enc k256_fis "$src/k256.f32" --max-error 200 --method fis --tile 0
enc kauai_full "$root/corpus/srtm3_N22W160_kauai.hgt" --max-error 1 --tile 0
enc kauai_full_t256 "$root/corpus/srtm3_N22W160_kauai.hgt" --max-error 1 --tile 256
rm -r "$src"
echo "make_cases.sh: $(ls "$out"/*.vtz | wc -l) cases in $out" >&2
