// toRGBA packs heights into raster-dem RGBA that MapLibre's formulas read back within half a
// quantum; nodata packs the fill height; demEncoding gives the factors.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import { pathToFileURL } from 'node:url';
import path from 'node:path';
import { init, decode, toRGBA, decodeRGBA, demEncoding } from '../src/vtz.js';

await init(process.env.VTZ_WASM ? pathToFileURL(path.resolve(process.env.VTZ_WASM)) : new URL('../dist/vtz.wasm', import.meta.url));
const golden = (n) => fs.readFileSync(new URL(`../../tests/golden/${n}.vtz`, import.meta.url));

/** MapLibre's raster-dem unpacking (DEMData.getUnpackVector): R·rf + G·gf + B·bf − baseShift. */
function unpack(rgba, i, enc) {
  const [r, g, b, a] = [rgba[4 * i], rgba[4 * i + 1], rgba[4 * i + 2], rgba[4 * i + 3]];
  assert.equal(a, 255);
  if (enc.encoding === 'terrarium') return r * 256 + g + b / 256 - 32768;
  if (enc.encoding === 'mapbox') return (r * 65536 + g * 256 + b) / 10 - 10000;
  return r * enc.redFactor + g * enc.greenFactor + b * enc.blueFactor - enc.baseShift;
}

const heights = new Float32Array([0, -1.25, 1234.567, 8848.86, -431.7, NaN, 0.001953125, 32767.99, -32768, 1e9, -1e9]);
const decoded = { width: heights.length, height: 1, heights, nodata: NaN };

for (const [opts, tol] of [
  [{ encoding: 'terrarium' }, 1 / 512],
  [{ encoding: 'mapbox' }, 0.05],
  [{ encoding: 'custom', quantum: 0.01, baseShift: 11000 }, 0.005],
  [{ quantum: 0.25, baseShift: 500, fill: -7 }, 0.125],
]) {
  test(`round trip ${JSON.stringify(opts)} within ${tol}`, () => {
    const enc = demEncoding(opts);
    const q = enc.encoding === 'terrarium' ? 1 / 256 : enc.encoding === 'mapbox' ? 0.1 : enc.blueFactor;
    const base = enc.encoding === 'terrarium' ? 32768 : enc.encoding === 'mapbox' ? 10000 : enc.baseShift;
    const [lo, hi] = [-base, (2 ** 24 - 1) * q - base];
    const rgba = toRGBA(decoded, opts);
    assert.ok(rgba instanceof Uint8ClampedArray);
    assert.equal(rgba.length, 4 * heights.length);
    for (let i = 0; i < heights.length; i++) {
      const h = Number.isNaN(heights[i]) ? (opts.fill ?? 0) : Math.min(hi, Math.max(lo, heights[i]));
      const back = unpack(rgba, i, enc);
      assert.ok(Math.abs(back - h) <= tol + 1e-9 * Math.abs(h), `${heights[i]} → ${back}`);
    }
  });
}

test('a vtz stream packs like its decode, nodata to the fill', () => {
  const bytes = golden('v5_kauai_tiles');
  const d = decode(bytes);
  for (const opts of [{ encoding: 'terrarium', fill: -5 }, { quantum: 0.5, baseShift: 1000 }]) {
    const { width, height, rgba } = decodeRGBA(bytes, opts);
    assert.equal(width, d.width);
    assert.equal(height, d.height);
    assert.deepEqual(rgba, toRGBA(d, opts));
    const enc = demEncoding(opts);
    const q = opts.quantum ?? 1 / 256;
    for (let i = 0; i < d.heights.length; i++) {
      const h = Number.isNaN(d.heights[i]) ? (opts.fill ?? 0) : d.heights[i];
      assert.ok(Math.abs(unpack(rgba, i, enc) - h) <= q / 2 + 1e-9, `sample ${i}`);
    }
  }
  // Nodata heights given as the nodata value (decode {nodata: 'value'}) are just heights.
  const withNodata = decode(golden('v1_kauai_crop_residual_exceptions'));
  const holes = withNodata.heights.filter(Number.isNaN).length;
  const rgba = toRGBA(withNodata, { fill: 0 });
  let zero = 0;
  for (let i = 0; i < withNodata.heights.length; i++) if (unpack(rgba, i, { encoding: 'terrarium' }) === 0) zero++;
  assert.ok(zero >= holes);
});

test('demEncoding gives MapLibre factors', () => {
  assert.deepEqual(demEncoding(), { encoding: 'terrarium' });
  assert.deepEqual(demEncoding({ encoding: 'mapbox' }), { encoding: 'mapbox' });
  assert.deepEqual(demEncoding({ quantum: 0.125, baseShift: 1000 }), {
    encoding: 'custom',
    redFactor: 8192,
    greenFactor: 32,
    blueFactor: 0.125,
    baseShift: 1000,
  });
  assert.throws(() => demEncoding({ encoding: 'jpeg' }), TypeError);
  assert.throws(() => toRGBA(decoded, { quantum: 0 }), /quantum/);
  assert.throws(() => toRGBA(decoded, { quantum: 1, fill: NaN }), /finite/);
});
