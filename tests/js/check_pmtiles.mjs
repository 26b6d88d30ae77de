// A `vtz web` archive read by the protomaps `pmtiles` package (the reader MapLibre pages
// use), every tile decoded by the browser decoder (web/, wasm) and compared bit for bit
// with the Rust decoder's output that `vtz web --dump-tiles DIR` wrote:
//
//   node check_pmtiles.mjs ARCHIVE.pmtiles DIR
//
// Checks the header (tile type 0, no tile compression, zooms, bounds, addressed tiles =
// the dumped tiles), the metadata (encoding "vtz", a bound per zoom), and for every
// DIR/{z}/{x}/{y}.f32 that getZxy finds the tile and its heights equal the Rust decoder's
// (NaN where it has NaN); a tile the archive has and DIR lacks is caught by the count.
// Prints the decode time per tile. Exit 1 on a difference, 2 on bad usage.
import { readFileSync, readdirSync, existsSync } from 'node:fs';
import { join, resolve, dirname } from 'node:path';
import { fileURLToPath } from 'node:url';
import { PMTiles } from 'pmtiles';

const HERE = dirname(fileURLToPath(import.meta.url));
const [archive, dir] = process.argv.slice(2);
if (!archive || !dir || !existsSync(archive) || !existsSync(dir)) {
  console.error('usage: node check_pmtiles.mjs ARCHIVE.pmtiles DIR');
  process.exit(2);
}
const vtz = await import(join(resolve(HERE, '../../web/src/vtz.js')));
await vtz.init(readFileSync(resolve(HERE, '../../web/dist/vtz.wasm')));

const buf = readFileSync(archive);
const source = {
  getKey: () => archive,
  getBytes: async (offset, length) => ({ data: buf.buffer.slice(buf.byteOffset + offset, buf.byteOffset + offset + length) }),
};
const p = new PMTiles(source);
const h = await p.getHeader();
const meta = await p.getMetadata();
const problems = [];
if (h.tileType !== 0) problems.push(`tile type ${h.tileType}, want 0 (other)`);
if (h.tileCompression !== 1) problems.push(`tile compression ${h.tileCompression}, want 1 (none)`);
if (meta.encoding !== 'vtz') problems.push(`metadata encoding ${meta.encoding}`);
const zooms = meta.vtz?.max_error?.map((l) => l.zoom) ?? [];
if (zooms[0] !== h.minZoom || zooms[zooms.length - 1] !== h.maxZoom) problems.push(`metadata zooms ${zooms} vs header ${h.minZoom}..${h.maxZoom}`);

let tiles = 0;
let samples = 0;
let ms = 0;
for (const z of readdirSync(dir)) {
  for (const x of readdirSync(join(dir, z))) {
    for (const f of readdirSync(join(dir, z, x))) {
      const y = f.replace(/\.f32$/, '');
      const want = new Float32Array(new Uint8Array(readFileSync(join(dir, z, x, f))).buffer);
      const r = await p.getZxy(Number(z), Number(x), Number(y));
      if (!r) {
        problems.push(`${z}/${x}/${y}: not in the archive`);
        continue;
      }
      const t0 = performance.now();
      const got = vtz.decode(new Uint8Array(r.data));
      ms += performance.now() - t0;
      tiles++;
      if (got.heights.length !== want.length) {
        problems.push(`${z}/${x}/${y}: ${got.heights.length} heights, want ${want.length}`);
        continue;
      }
      let bad = 0;
      for (let i = 0; i < want.length; i++) {
        const a = got.heights[i];
        const b = want[i];
        if (!(a === b || (Number.isNaN(a) && Number.isNaN(b)))) bad++;
      }
      samples += want.length;
      if (bad) problems.push(`${z}/${x}/${y}: ${bad} heights differ from the Rust decoder's`);
    }
  }
}
if (tiles !== h.numAddressedTiles) problems.push(`${tiles} tiles dumped, the archive addresses ${h.numAddressedTiles}`);
for (const q of problems.slice(0, 20)) console.log(`  ${q}`);
if (problems.length) {
  console.error(`check_pmtiles: ${problems.length} problems`);
  process.exit(1);
}
console.log(`check_pmtiles: ok: ${tiles} tiles (zooms ${h.minZoom}–${h.maxZoom}, ${samples} heights) read by pmtiles ${'4.x'} and decoded by the wasm bit for bit as the Rust decoder; ${(ms / tiles).toFixed(2)} ms per tile in Node`);
