// node benches/web/decode.mjs OUTDIR [DATASET...]: decode time per tile in headless Chromium
// (Debian's /usr/bin/chromium, or $CHROMIUM; playwright-core). Serves decode.html, page.js,
// pmt.js, web/ (src, dist), node_modules/lerc and OUTDIR's archives from 127.0.0.1 with
// COOP/COEP (5 µs timers), runs page.js's runBench per dataset, prints JSON.
// VTZ_WASM another vtz.wasm; VTZ_WEB_PASSES (default 5) timed passes after one warm-up pass.
import { createServer } from 'node:http';
import { readFileSync, existsSync, statSync } from 'node:fs';
import { dirname, extname, join, resolve, sep } from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

const HERE = dirname(fileURLToPath(import.meta.url));
const ROOT = resolve(HERE, '../..');
const out = resolve(process.argv[2] ?? '/tmp/vtz-web-bench');
const datasets = process.argv.length > 3 ? process.argv.slice(3) : ['kauai512', 'srtm1_512', 'kauai256'];
const passes = Number(process.env.VTZ_WEB_PASSES ?? 5);
const FORMATS = ['vtz-0.25', 'vtz-0.1', 'vtz-0.05', 'terrarium-png', 'terrarium-webp', 'libwebp', 'mapbox-png',
  'lerc-0.25', 'lerc-0.1', 'lerc-0.05'];
const TYPES = { '.html': 'text/html', '.js': 'text/javascript', '.mjs': 'text/javascript', '.wasm': 'application/wasm' };
// VTZ_WASM: the vtz.wasm to serve as /web/dist/vtz.wasm (run.sh passes a snapshot).
const WASM = resolve(process.env.VTZ_WASM ?? join(ROOT, 'web/dist/vtz.wasm'));
const MOUNTS = [['/web/dist/vtz.wasm', WASM], ['/web/', join(ROOT, 'web')], ['/lerc/', join(HERE, 'node_modules/lerc')], ['/data/', out], ['/', HERE]];

const server = createServer((req, res) => {
  const path = decodeURIComponent(new URL(req.url, 'http://x').pathname);
  for (const [prefix, dir] of MOUNTS) {
    if (!path.startsWith(prefix)) continue;
    if (!prefix.endsWith('/') && path !== prefix) continue;
    const file = prefix.endsWith('/') ? resolve(dir, '.' + path.slice(prefix.length - 1)) : dir;
    if (!(file + sep).startsWith(dir + sep) && file !== dir) break;
    if (!existsSync(file) || !statSync(file).isFile()) break;
    res.writeHead(200, {
      'content-type': TYPES[extname(file)] ?? 'application/octet-stream',
      'cross-origin-opener-policy': 'same-origin', 'cross-origin-embedder-policy': 'require-corp',
      'cache-control': 'no-store',
    });
    res.end(readFileSync(file));
    return;
  }
  if (path !== '/favicon.ico') console.error(`404 ${path}`);
  res.writeHead(path === '/favicon.ico' ? 204 : 404).end();
});
await new Promise((r) => server.listen(0, '127.0.0.1', r));
const origin = `http://127.0.0.1:${server.address().port}`;
const launchArgs = [
  '--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
  '--disable-background-networking', '--disable-component-update', '--disable-sync',
  '--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1',
];
const browser = await chromium.launch({ executablePath: process.env.CHROMIUM ?? '/usr/bin/chromium', headless: true, args: launchArgs });
const report = { chromium: browser.version(), passes, wasm: WASM, datasets: {} };
try {
  for (const dataset of datasets) {
    const page = await browser.newPage();
    const errors = [];
    page.on('pageerror', (e) => errors.push(String(e)));
    page.on('console', (m) => { if (m.type() === 'error') errors.push(m.text()); });
    await page.goto(`${origin}/decode.html`);
    await page.waitForFunction(() => window.ready === true, null, { timeout: 60000 });
    const formats = FORMATS.filter((f) => existsSync(join(out, `${dataset}.${f}.pmtiles`)));
    const t0 = Date.now();
    const r = await page.evaluate((cfg) => window.runBench(cfg), { dataset, formats, passes, worker: true });
    if (errors.length) throw new Error(`page errors: ${errors.join('; ')}`);
    report.datasets[dataset] = r;
    console.error(`${dataset}: ${((Date.now() - t0) / 1000).toFixed(0)} s, crossOriginIsolated ${r.crossOriginIsolated}`);
    for (const [k, v] of Object.entries(r.results)) console.error(`  ${k}: finest ${v.finest.toFixed(2)} ms, all ${v.all.toFixed(2)} ms`);
    await page.close();
  }
} finally {
  await browser.close();
  server.close();
}
console.log(JSON.stringify(report, null, 1));
