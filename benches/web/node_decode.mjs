// node benches/web/node_decode.mjs OUTDIR: the wasm decoder (web/src/vtz.js) in Node on every
// vtz tile of OUTDIR's archives, for reference beside Chromium: per tile, decode to
// Float32Array and decode + Terrarium RGBA, after a warm-up pass; medians over passes × tiles
// (finest zoom and all zooms). VTZ_WASM: another vtz.wasm (absolute path). Prints JSON.
import fs from 'node:fs';
import { init, decode, decodeRGBA } from '../../web/src/vtz.js';
import { readArchive } from './pmt.js';

const out = process.argv[2];
const passes = Number(process.env.VTZ_WEB_PASSES ?? 5);
await init(process.env.VTZ_WASM ? new URL(`file://${process.env.VTZ_WASM}`) : new URL('../../web/dist/vtz.wasm', import.meta.url));
const median = (/** @type {number[]} */ a) => { const s = [...a].sort((x, y) => x - y); return s.length ? s[s.length >> 1] : NaN; };
const res = {};
for (const f of fs.readdirSync(out).filter((f) => /\.vtz-[\d.]+\.pmtiles$/.test(f)).sort()) {
  const a = await readArchive(new Uint8Array(fs.readFileSync(`${out}/${f}`)).buffer);
  const r = {};
  for (const [op, fn] of [['decode', (b) => decode(b)], ['decode+rgba', (b) => decodeRGBA(b, { encoding: 'terrarium' })]]) {
    const fin = [], all = [];
    for (let p = -1; p < passes; p++) {
      for (const t of a.tiles) {
        const t0 = performance.now();
        fn(t.bytes);
        const dt = performance.now() - t0;
        if (p < 0) continue;
        all.push(dt);
        if (t.z === a.maxZoom) fin.push(dt);
      }
    }
    r[op] = { finest: median(fin), all: median(all), n_finest: fin.length / passes, n_all: all.length / passes };
  }
  res[f.replace('.pmtiles', '')] = r;
  console.error(f, JSON.stringify(r));
}
console.log(JSON.stringify({ node: process.version, passes, results: res }, null, 1));
