// The page decode.mjs opens (served from 127.0.0.1, cross-origin isolated so that
// performance.now() has 5 µs resolution): fetches each archive whole, parses it (pmt.js), and
// times per tile, after a warm-up pass, for `passes` passes in which every format takes its
// turn on every tile (paired against the machine's noise):
//   vtz: decode (wasm, to Float32Array), decode + Terrarium RGBA packing (main thread), and
//        the same through a one-worker VtzDecoder (round trip, transfer);
//   PNG/WebP: createImageBitmap(blob) alone, and + OffscreenCanvas drawImage + getImageData
//        (how MapLibre reads raster-dem pixels);
//   LERC: Esri's lerc 4.2.0 decode (wasm).
import { init, decode, decodeRGBA } from '/web/src/vtz.js';
import { VtzDecoder } from '/web/src/client.js';
import * as Lerc from '/lerc/LercDecode.es.js';
import { readArchive } from './pmt.js';

const MIME = { 'terrarium-png': 'image/png', 'mapbox-png': 'image/png', 'terrarium-webp': 'image/webp', libwebp: 'image/webp' };
const median = (a) => { const s = [...a].sort((x, y) => x - y); return s.length ? s[s.length >> 1] : NaN; };

async function bitmap(blob) {
  return createImageBitmap(blob, { premultiplyAlpha: 'none', colorSpaceConversion: 'none' });
}
let canvas = null, ctx = null;
async function pixels(blob) {
  const bm = await bitmap(blob);
  if (!canvas || canvas.width !== bm.width) {
    canvas = new OffscreenCanvas(bm.width, bm.height);
    ctx = canvas.getContext('2d', { willReadFrequently: true });
  }
  ctx.drawImage(bm, 0, 0);
  const d = ctx.getImageData(0, 0, bm.width, bm.height).data;
  bm.close();
  return d;
}

export async function runBench({ dataset, formats, passes, worker }) {
  await init('/web/dist/vtz.wasm');
  await Lerc.load({ locateFile: (f) => `/lerc/${f}` });
  const dec = worker ? new VtzDecoder({ workers: 1, workerUrl: '/web/src/worker.js', wasmUrl: '/web/dist/vtz.wasm' }) : null;
  /** @type {{name: string, fn: (t: any) => any, tiles: any[], maxZoom: number}[]} */
  const series = [];
  for (const fmt of formats) {
    const a = await readArchive(await (await fetch(`/data/${dataset}.${fmt}.pmtiles`)).arrayBuffer());
    const tiles = a.tiles.map((t) => ({ ...t, copy: t.bytes.slice(), blob: MIME[fmt] ? new Blob([t.bytes], { type: MIME[fmt] }) : null }));
    const add = (op, fn) => series.push({ name: `${fmt}/${op}`, fn, tiles, maxZoom: a.maxZoom });
    if (fmt.startsWith('vtz')) {
      add('decode', (t) => decode(t.bytes));
      add('decode+rgba', (t) => decodeRGBA(t.bytes, { encoding: 'terrarium' }));
      if (dec) add('worker decode+rgba', (t) => dec.decodeRGBA(t.bytes, { encoding: 'terrarium' }));
    } else if (MIME[fmt]) {
      add('createImageBitmap', async (t) => (await bitmap(t.blob)).close());
      add('bitmap+getImageData', (t) => pixels(t.blob));
    } else if (fmt.startsWith('lerc')) {
      add('decode', (t) => Lerc.decode(t.copy));
    }
  }
  const times = series.map(() => ({ fin: [], all: [], pass: [] }));
  for (let p = -1; p < passes; p++) {
    for (let s = 0; s < series.length; s++) {
      const { fn, tiles, maxZoom } = series[s];
      const passTimes = [];
      for (const t of tiles) {
        const t0 = performance.now();
        await fn(t);
        const dt = performance.now() - t0;
        if (p < 0) continue;
        times[s].all.push(dt);
        if (t.z === maxZoom) { times[s].fin.push(dt); passTimes.push(dt); }
      }
      if (p >= 0) times[s].pass.push(median(passTimes));
    }
  }
  if (dec) await dec.terminate();
  const res = {};
  series.forEach((s, i) => {
    const pm = times[i].pass;
    res[s.name] = {
      finest: median(times[i].fin), all: median(times[i].all),
      n_finest: times[i].fin.length / passes, n_all: times[i].all.length / passes,
      pass_medians_min: Math.min(...pm), pass_medians_max: Math.max(...pm),
    };
  });
  return { crossOriginIsolated, userAgent: navigator.userAgent, results: res };
}
