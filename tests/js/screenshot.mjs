// Renders vtz's outputs in a real browser and checks the pictures are not blank:
//
//   node screenshot.mjs [--tiles DIR] [--glb FILE.glb] --out PREFIX [--timeout SECONDS]
//   node screenshot.mjs --measure FILE.png...     (print the blank-check values of PNGs)
//
// Serves view/ (terrain.html: CesiumJS on the quantized-mesh tiles; glb.html: three.js on the
// .glb), node_modules/, DIR at /tiles/ and FILE.glb at /mesh.glb from 127.0.0.1, drives
// Debian's Chromium (/usr/bin/chromium, or $CHROMIUM) headless with playwright-core and
// software WebGL (SwiftShader), waits for the page's window.ready (default 120 s), and writes
// PREFIX-terrain.png and PREFIX-glb.png (1024 × 768). Fails (exit 1) when a page reports a
// JavaScript error, a tile listed in layer.json's `available` is not served (404), the page
// asks for anything off this machine, Cesium's sampled heights are flat, or a picture is
// blank: fewer than MIN_COLOURS distinct colours or a luminance standard deviation below
// MIN_LUMA_STD. Exit 2 on bad usage.
import { createServer } from 'node:http';
import { closeSync, createReadStream, existsSync, openSync, readFileSync, readSync, statSync } from 'node:fs';
import { dirname, extname, join, resolve, sep } from 'node:path';
import { fileURLToPath } from 'node:url';
import { MIN_COLOURS, MIN_LUMA_STD, TYPES, blank, describe, launch, measure } from './harness.mjs';

const HERE = dirname(fileURLToPath(import.meta.url));
const SIZE = { width: 1024, height: 768 };

function usage(msg) {
  if (msg) console.error(`screenshot: ${msg}`);
  console.error('usage: node screenshot.mjs [--tiles DIR] [--glb FILE.glb] --out PREFIX [--timeout SECONDS]\n' +
    '       node screenshot.mjs --measure FILE.png...');
  process.exit(2);
}


// ---- arguments
const argv = process.argv.slice(2);
if (argv[0] === '--measure') {
  if (argv.length < 2) usage();
  let bad = 0;
  for (const f of argv.slice(1)) {
    const m = measure(f);
    if (blank(m)) bad++;
    console.log(`${blank(m) ? 'BLANK' : 'ok   '} ${f}: ${describe(m)}`);
  }
  process.exit(bad ? 1 : 0);
}
const opts = { timeout: 120 };
for (let i = 0; i < argv.length; i++) {
  const a = argv[i];
  const val = () => (i + 1 < argv.length ? argv[++i] : usage(`${a} needs a value`));
  if (a === '--tiles') opts.tiles = val();
  else if (a === '--glb') opts.glb = val();
  else if (a === '--out') opts.out = val();
  else if (a === '--timeout') opts.timeout = Number(val());
  else usage(`unknown argument ${a}`);
}
if (!opts.out || (!opts.tiles && !opts.glb) || !(opts.timeout > 0)) usage();
if (opts.tiles && !existsSync(join(opts.tiles, 'layer.json'))) usage(`${opts.tiles}: no layer.json`);
if (opts.glb && !existsSync(opts.glb)) usage(`${opts.glb}: no such file`);
const chromePath = process.env.CHROMIUM ?? '/usr/bin/chromium';
if (!existsSync(chromePath)) usage(`${chromePath} not found (apt-get install chromium)`);

// Tiles layer.json lists, "z/x/y".
const available = new Set();
if (opts.tiles) {
  const layer = JSON.parse(readFileSync(join(opts.tiles, 'layer.json'), 'utf8'));
  (layer.available ?? []).forEach((ranges, z) => {
    for (const r of ranges) {
      for (let x = r.startX; x <= r.endX; x++) for (let y = r.startY; y <= r.endY; y++) available.add(`${z}/${x}/${y}`);
    }
  });
}

// ---- the server
const roots = [
  ['/view/', join(HERE, 'view')],
  ['/node_modules/', join(HERE, 'node_modules')],
  ...(opts.tiles ? [['/tiles/', resolve(opts.tiles)]] : []),
];
const served = { tiles: 0, tileBytes: 0, requests: 0 };
const problems = [];
const notes = [];

function fileFor(pathname) {
  if (pathname === '/mesh.glb' && opts.glb) return resolve(opts.glb);
  for (const [prefix, root] of roots) {
    if (!pathname.startsWith(prefix)) continue;
    const f = resolve(root, `.${sep}${decodeURIComponent(pathname.slice(prefix.length))}`);
    return f.startsWith(root + sep) ? f : undefined;
  }
  return undefined;
}
const server = createServer((req, res) => {
  served.requests++;
  const url = new URL(req.url, 'http://localhost');
  const f = fileFor(url.pathname);
  const tile = /^\/tiles\/(\d+\/\d+\/\d+)\.terrain$/.exec(url.pathname);
  if (!f || !existsSync(f) || !statSync(f).isFile()) {
    if (tile && available.has(tile[1])) problems.push(`tile ${tile[1]} is listed in layer.json but the server has no ${url.pathname}`);
    else if (tile) notes.push(`Cesium asked for ${url.pathname}, which layer.json does not list`);
    else if (url.pathname !== '/favicon.ico') notes.push(`404 ${url.pathname}`);
    res.writeHead(404, { 'content-type': 'text/plain' });
    res.end('not found');
    return;
  }
  const headers = { 'content-type': TYPES[extname(f)] ?? 'application/octet-stream', 'cache-control': 'no-store' };
  if (tile) {
    served.tiles++;
    served.tileBytes += statSync(f).size;
    const head = Buffer.alloc(2);
    const fd = openSync(f, 'r');
    readSync(fd, head, 0, 2, 0);
    closeSync(fd);
    if (head[0] === 0x1f && head[1] === 0x8b) headers['content-encoding'] = 'gzip';
  }
  res.writeHead(200, headers);
  createReadStream(f).pipe(res);
});
await new Promise((ok) => server.listen(0, '127.0.0.1', ok));
const origin = `http://127.0.0.1:${server.address().port}`;

// ---- the browser
const t0 = Date.now();
const browser = await launch();
const results = [];
try {
  const pages = [];
  if (opts.tiles) pages.push(['terrain', 'terrain.html']);
  if (opts.glb) pages.push(['glb', 'glb.html']);
  for (const [name, html] of pages) {
    const context = await browser.newContext({ viewport: SIZE, deviceScaleFactor: 1 });
    const page = await context.newPage();
    const pageProblems = [];
    page.on('console', (msg) => {
      if ((msg.type() === 'error' || msg.type() === 'warning') && !msg.text().includes('GL Driver Message')) console.log(`  [${name} console.${msg.type()}] ${msg.text()}`);
    });
    page.on('pageerror', (e) => pageProblems.push(`JavaScript error: ${e.message}`));
    page.on('request', (r) => {
      const u = r.url();
      if (!u.startsWith(origin) && !u.startsWith('data:') && !u.startsWith('blob:')) pageProblems.push(`asked for ${u}, off this machine`);
    });
    const answered = new Set();
    page.on('response', (r) => {
      if (r.status() >= 400) console.log(`  [${name}] HTTP ${r.status()} ${r.url()}`);
      else answered.add(r.url());
    });
    page.on('requestfailed', (r) => {
      const why = r.failure()?.errorText;
      // Chromium sometimes reports a fetch whose body was read to the end (the page then
      // rendered it) as aborted; a request that got its answer is not a failure.
      if (why === 'net::ERR_ABORTED' && answered.has(r.url())) return;
      pageProblems.push(`request failed: ${r.url()} (${why})`);
    });
    const t1 = Date.now();
    await page.goto(`${origin}/view/${html}`);
    try {
      await page.waitForFunction(() => window.ready === true || window.failed !== undefined, null, { timeout: opts.timeout * 1000, polling: 250 });
    } catch {
      pageProblems.push(`window.ready not set within ${opts.timeout} s`);
    }
    const state = await page.evaluate(() => ({ ready: window.ready, errors: window.errors ?? [], stats: window.stats, webgl: (() => {
      const gl = document.createElement('canvas').getContext('webgl2');
      const ext = gl?.getExtension('WEBGL_debug_renderer_info');
      return gl ? gl.getParameter(ext ? ext.UNMASKED_RENDERER_WEBGL : gl.RENDERER) : 'no WebGL 2';
    })() }));
    pageProblems.push(...state.errors);
    const file = `${opts.out}-${name}.png`;
    await page.screenshot({ path: file });
    const m = measure(file);
    if (blank(m)) pageProblems.push(`${file} looks blank: ${describe(m)} (want ≥ ${MIN_COLOURS} colours and luminance std ≥ ${MIN_LUMA_STD})`);
    const s = state.stats ?? {};
    if (name === 'terrain') {
      if (served.tiles === 0) pageProblems.push('no tile was served');
      if (!(s.sampled > 0) || !(s.sampledMaxHeight > s.sampledMinHeight)) {
        pageProblems.push(`Cesium's sampled heights are flat or missing: ${JSON.stringify(s)}`);
      }
    } else if (!(s.triangles > 0)) {
      pageProblems.push(`three.js loaded no triangles: ${JSON.stringify(s)}`);
    }
    const secs = ((Date.now() - t1) / 1000).toFixed(1);
    const info = state.stats === undefined ? 'the page set no stats' : name === 'terrain'
      ? `${served.tiles} tiles served (${(served.tileBytes / 1e6).toFixed(2)} MB), ${s.tilesRendered} rendered at levels ${JSON.stringify(s.levelsRendered)}, ` +
        `sampled heights ${s.sampledMinHeight?.toFixed(1)}..${s.sampledMaxHeight?.toFixed(1)} m over ${s.sampled} points`
      : `${s.meshes} meshes, ${s.vertices} vertices, ${s.triangles} triangles, ${s.withNormals} with normals, size ${JSON.stringify(s.size?.map((v) => +v.toFixed(1)))}`;
    console.log(`${pageProblems.length ? 'FAIL' : 'ok  '} ${name}: ${file}: ${describe(m)}; ${info}; ${secs} s (${state.webgl})`);
    for (const p of pageProblems) console.log(`  ${name}: ${p}`);
    results.push(...pageProblems.map((p) => `${name}: ${p}`));
    await context.close();
  }
} finally {
  await browser.close();
  server.close();
}
for (const n of [...new Set(notes)]) console.log(`  note: ${n}`);
const uniqueProblems = [...new Set(problems)];
for (const p of uniqueProblems.slice(0, 20)) console.log(`  terrain: ${p}`);
if (uniqueProblems.length > 20) console.log(`  terrain: ... and ${uniqueProblems.length - 20} more tiles not served`);
results.push(...uniqueProblems);
if (results.length) {
  console.error(`screenshot: ${results.length} problems (${((Date.now() - t0) / 1000).toFixed(1)} s)`);
  process.exit(1);
}
console.log(`screenshot: ok (${((Date.now() - t0) / 1000).toFixed(1)} s)`);
