// MapLibre GL JS renders a `vtz web` archive in headless Chromium, decoded in the browser
// by web/ (wasm in a worker), and the same view from a Terrarium PNG archive of the same
// pyramid agrees with it:
//
//   node maplibre.mjs --vtz A.pmtiles --terrarium B.pmtiles --out PREFIX
//                     [--center LON,LAT --zoom Z] [--timeout SECONDS]
//
// Serves web/ (the demo page web/demo/, the decoder), tests/js/node_modules (maplibre-gl,
// pmtiles) and the two archives from 127.0.0.1 with byte ranges, and checks:
// - 3D terrain + hillshade from the vtz archive (PREFIX-3d.png): no JavaScript error, no
//   request off this machine, no failed request or tile, tiles decoded, not blank, the
//   terrain's heights at 25 points vary, and match the Terrarium render's within the
//   archive's bound (+ Terrarium's 1/512 m) at the coarsest zoom the view can draw;
// - hillshade seen from above (PREFIX-hillshade-vtz.png, -terrarium.png, -diff.png): the
//   two renders differ along the tile edges no more than elsewhere (no seam): the mean
//   |Δ luminance| of the pixel columns and rows on the edges ≤ 2 × that of the whole
//   picture + 1 grey level; and the luminance step across the vtz render's edges is no
//   larger than the Terrarium render's (+ 1 grey level).
// Prints the first-render times. Exit 1 on a problem, 2 on bad usage.
import { mkdirSync, readFileSync, writeFileSync } from 'node:fs';
import { basename, dirname, join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';
import pngjs from 'pngjs';
import { blank, describe, launch, measure, renderer, serve, watch } from './harness.mjs';

const { PNG } = pngjs;
const HERE = dirname(fileURLToPath(import.meta.url));
const REPO = resolve(HERE, '../..');
// Hillshade from above at 1024 × 768 (tile edges cross it); 3D at 800 × 600, which
// software WebGL draws in about half the time.
const SIZE = { width: 1024, height: 768 };
const SIZE_3D = { width: 800, height: 600 };

function usage(msg) {
  if (msg) console.error(`maplibre: ${msg}`);
  console.error('usage: node maplibre.mjs --vtz A.pmtiles --terrarium B.pmtiles --out PREFIX [--center LON,LAT --zoom Z] [--timeout SECONDS]');
  process.exit(2);
}
const opts = { timeout: 240 };
const argv = process.argv.slice(2);
for (let i = 0; i < argv.length; i++) {
  const a = argv[i];
  const val = () => (i + 1 < argv.length ? argv[++i] : usage(`${a} needs a value`));
  if (a === '--vtz') opts.vtz = val();
  else if (a === '--terrarium') opts.terrarium = val();
  else if (a === '--out') opts.out = val();
  else if (a === '--center') opts.center = val();
  else if (a === '--zoom') opts.zoom = val();
  else if (a === '--timeout') opts.timeout = Number(val());
  else usage(`unknown argument ${a}`);
}
if (!opts.vtz || !opts.terrarium || !opts.out || !(opts.timeout > 0)) usage();
mkdirSync(dirname(resolve(opts.out)), { recursive: true });

const server = await serve([
  ['/web/', join(REPO, 'web')],
  ['/node_modules/', join(HERE, 'node_modules')],
  ['/a/vtz/', dirname(resolve(opts.vtz))],
  ['/a/terrarium/', dirname(resolve(opts.terrarium))],
]);
const vtzUrl = `/a/vtz/${basename(opts.vtz)}`;
const terrariumUrl = `/a/terrarium/${basename(opts.terrarium)}`;
const problems = [];
const browser = await launch();

/** Load the demo with `query`, wait for window.ready, screenshot to `file`. */
async function render(name, query, file, viewport = SIZE) {
  const context = await browser.newContext({ viewport, deviceScaleFactor: 1 });
  const page = await context.newPage();
  const pageProblems = watch(page, server.origin, name);
  const t = Date.now();
  await page.goto(`${server.origin}/web/demo/index.html?${new URLSearchParams(query)}`);
  try {
    await page.waitForFunction(() => window.ready === true || window.failed !== undefined, null, { timeout: opts.timeout * 1000, polling: 250 });
  } catch {
    pageProblems.push(`window.ready not set within ${opts.timeout} s`);
  }
  const state = await page.evaluate(() => ({ ready: window.ready, failed: window.failed, errors: window.errors ?? [], stats: window.stats }));
  pageProblems.push(...state.errors);
  await page.screenshot({ path: file });
  const m = measure(file);
  if (blank(m)) pageProblems.push(`${file} looks blank: ${describe(m)}`);
  const s = state.stats ?? {};
  if (s.source === 'vtz') {
    if (!(s.vtz?.tiles > 0)) pageProblems.push(`no vtz tile was decoded: ${JSON.stringify(s.vtz)}`);
    if (s.vtz?.errors) pageProblems.push(`${s.vtz.errors} vtz tiles failed`);
  }
  const gl = await renderer(page);
  const vt = s.vtz ?? {};
  console.log(`${pageProblems.length ? 'FAIL' : 'ok  '} ${name}: ${file}: ${describe(m)}; first render ${s.firstRenderMs?.toFixed(0)} ms` +
    (s.source === 'vtz' ? `; ${vt.tiles} vtz tiles (${(vt.bytes / 1024).toFixed(0)} KB), ${vt.empty} empty, ${(vt.decodeMs / Math.max(1, vt.tiles)).toFixed(1)} ms per tile from request to bitmap (queueing and the workers' start included)` : '') +
    `; ${((Date.now() - t) / 1000).toFixed(1)} s (${gl})`);
  for (const p of pageProblems) console.log(`  ${name}: ${p}`);
  problems.push(...pageProblems.map((p) => `${name}: ${p}`));
  await context.close();
  return s;
}

const lum = (png, x, y) => {
  const i = 4 * (y * png.width + x);
  return 0.2126 * png.data[i] + 0.7152 * png.data[i + 1] + 0.0722 * png.data[i + 2];
};

const meta = await (async () => {
  // The vtz archive's metadata, read the way the spec says (for the bounds per zoom).
  const { PMTiles } = await import('pmtiles');
  const buf = readFileSync(opts.vtz);
  const src = { getKey: () => 'vtz', getBytes: async (o, l) => ({ data: buf.buffer.slice(buf.byteOffset + o, buf.byteOffset + o + l) }) };
  const p = new PMTiles(src);
  return { header: await p.getHeader(), metadata: await p.getMetadata() };
})();
const bounds = new Map(meta.metadata.vtz.max_error.map((l) => [l.zoom, l.bound]));
const view = { ...(opts.center ? { center: opts.center } : {}), ...(opts.zoom ? { zoom: opts.zoom } : {}) };

try {
  // 3D terrain, both sources; heights compared.
  const v3 = await render('3d-vtz', { vtz: vtzUrl, mode: '3d', ...view }, `${opts.out}-3d.png`, SIZE_3D);
  const t3 = await render('3d-terrarium', { terrarium: terrariumUrl, mode: '3d', ...view }, `${opts.out}-3d-terrarium.png`, SIZE_3D);
  const hv = (v3.heights ?? []).map((h) => h[2]);
  const ht = (t3.heights ?? []).map((h) => h[2]);
  const valid = hv.filter((h) => h !== null);
  if (valid.length < 20 || Math.max(...valid) - Math.min(...valid) < 50) {
    problems.push(`3d: the terrain's heights are flat or missing: ${JSON.stringify(hv)}`);
  }
  // The coarsest tiles a pitched view draws are a few zooms above the centre's.
  const zMin = Math.max(meta.header.minZoom, (v3.edges?.z ?? 0) - 3);
  const tol = (bounds.get(zMin) ?? Infinity) + 1 / 512 + 0.01;
  let worst = 0;
  hv.forEach((h, k) => {
    if (h !== null && ht[k] !== null) worst = Math.max(worst, Math.abs(h - ht[k]));
  });
  console.log(`     3d heights: ${Math.min(...valid).toFixed(1)}..${Math.max(...valid).toFixed(1)} m at ${valid.length} points; largest |vtz − Terrarium| ${worst.toFixed(2)} m (bound at zoom ${zMin}: ${tol.toFixed(2)} m)`);
  if (!(worst <= tol)) problems.push(`3d: vtz and Terrarium terrain differ by ${worst} m at a sampled point, over ${tol}`);

  // Hillshade from above: the seam check.
  const hillVtz = await render('hillshade-vtz', { vtz: vtzUrl, mode: 'hillshade', ...view }, `${opts.out}-hillshade-vtz.png`);
  await render('hillshade-terrarium', { terrarium: terrariumUrl, mode: 'hillshade', ...view }, `${opts.out}-hillshade-terrarium.png`);
  const a = PNG.sync.read(readFileSync(`${opts.out}-hillshade-vtz.png`));
  const b = PNG.sync.read(readFileSync(`${opts.out}-hillshade-terrarium.png`));
  const diff = new PNG({ width: a.width, height: a.height });
  let all = 0;
  for (let y = 0; y < a.height; y++) {
    for (let x = 0; x < a.width; x++) {
      const d = Math.abs(lum(a, x, y) - lum(b, x, y));
      all += d;
      const i = 4 * (y * a.width + x);
      const v = Math.min(255, 8 * d);
      diff.data[i] = v;
      diff.data[i + 1] = v;
      diff.data[i + 2] = v;
      diff.data[i + 3] = 255;
    }
  }
  all /= a.width * a.height;
  writeFileSync(`${opts.out}-hillshade-diff.png`, PNG.sync.write(diff));
  const edges = hillVtz.edges ?? { xs: [], ys: [] };
  const xs = edges.xs.map(Math.round).filter((x) => x >= 2 && x < a.width - 2);
  const ys = edges.ys.map(Math.round).filter((y) => y >= 2 && y < a.height - 2);
  if (!xs.length || !ys.length) problems.push(`hillshade: no tile edge crosses the view: ${JSON.stringify(edges)}`);
  let onEdges = 0;
  let n = 0;
  let stepVtz = 0;
  let stepTer = 0;
  let m = 0;
  for (const x of xs) {
    for (let y = 0; y < a.height; y++) {
      for (let dx = -1; dx <= 1; dx++) {
        onEdges += Math.abs(lum(a, x + dx, y) - lum(b, x + dx, y));
        n++;
      }
      stepVtz += Math.abs(lum(a, x, y) - lum(a, x - 1, y));
      stepTer += Math.abs(lum(b, x, y) - lum(b, x - 1, y));
      m++;
    }
  }
  for (const y of ys) {
    for (let x = 0; x < a.width; x++) {
      for (let dy = -1; dy <= 1; dy++) {
        onEdges += Math.abs(lum(a, x, y + dy) - lum(b, x, y + dy));
        n++;
      }
      stepVtz += Math.abs(lum(a, x, y) - lum(a, x, y - 1));
      stepTer += Math.abs(lum(b, x, y) - lum(b, x, y - 1));
      m++;
    }
  }
  onEdges /= Math.max(1, n);
  stepVtz /= Math.max(1, m);
  stepTer /= Math.max(1, m);
  console.log(`     hillshade at zoom ${hillVtz.zoom?.toFixed(2)} (tiles of zoom ${edges.z}; edges at x ${JSON.stringify(xs)}, y ${JSON.stringify(ys)}): ` +
    `mean |Δ| vtz vs Terrarium ${all.toFixed(2)} over the picture, ${onEdges.toFixed(2)} on the tile edges; ` +
    `luminance step across the edges: vtz ${stepVtz.toFixed(2)}, Terrarium ${stepTer.toFixed(2)}`);
  if (!(onEdges <= 2 * all + 1)) problems.push(`hillshade: a seam: the renders differ by ${onEdges.toFixed(2)} on the tile edges, ${all.toFixed(2)} elsewhere`);
  if (!(stepVtz <= stepTer + 1)) problems.push(`hillshade: a seam: the vtz render steps by ${stepVtz.toFixed(2)} across the tile edges, Terrarium's by ${stepTer.toFixed(2)}`);
} finally {
  await browser.close();
  await server.close();
}
if (server.stats.missing.length) problems.push(`not found: ${[...new Set(server.stats.missing)].join(', ')}`);
if (problems.length) {
  console.error(`maplibre: ${problems.length} problems`);
  process.exit(1);
}
console.log(`maplibre: ok (${server.stats.requests} requests, ${server.stats.ranges} of them byte ranges)`);
