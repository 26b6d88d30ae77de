// The package in a real browser: headless Chromium (playwright-core from tests/js, Debian's
// /usr/bin/chromium or $CHROMIUM) loads web/src/client.js from a local HTTP server, decodes
// golden files in module workers to heights and to ImageBitmaps, and the page reads the
// bitmaps' pixels back: they must be the RGBA that toRGBA gives in Node, and the heights
// Node's. Skipped when playwright-core or Chromium is missing, unless VTZ_WEB_BROWSER=1.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import http from 'node:http';
import path from 'node:path';
import { createRequire } from 'node:module';
import { fileURLToPath } from 'node:url';
import { init, decode, toRGBA } from '../src/vtz.js';

const root = fileURLToPath(new URL('../../', import.meta.url));
const chromePath = process.env.CHROMIUM ?? '/usr/bin/chromium';
let chromium = null;
try {
  const require = createRequire(path.join(root, 'tests/js/package.json'));
  ({ chromium } = require('playwright-core'));
} catch {
  chromium = null;
}
const missing = !chromium ? 'playwright-core (npm ci --prefix tests/js)' : !fs.existsSync(chromePath) ? chromePath : null;
const skip = missing && process.env.VTZ_WEB_BROWSER !== '1' ? `no ${missing}` : false;

const names = ['v5_kauai_tiles', 'v1_kauai_crop_residual_lanes', 'v1_kauai_crop_residual_exceptions'];
const rgbaOpts = { encoding: 'custom', quantum: 0.25, baseShift: 1000, fill: -3 };

/** Serve the repository (web/ and tests/golden/) with the right types. */
function serve() {
  const types = { '.js': 'text/javascript', '.html': 'text/html', '.wasm': 'application/wasm', '.vtz': 'application/octet-stream' };
  const server = http.createServer((req, res) => {
    if (req.url === '/blank.html') {
      res.writeHead(200, { 'content-type': 'text/html' }).end('<!doctype html><title>vtz</title>');
      return;
    }
    const p = path.normalize(path.join(root, decodeURIComponent(new URL(req.url, 'http://x').pathname)));
    if (!p.startsWith(root) || !fs.existsSync(p) || !fs.statSync(p).isFile()) {
      res.writeHead(404).end();
      return;
    }
    res.writeHead(200, { 'content-type': types[path.extname(p)] ?? 'application/octet-stream' });
    fs.createReadStream(p).pipe(res);
  });
  return new Promise((resolve) => server.listen(0, '127.0.0.1', () => resolve(server)));
}

test('headless Chromium: workers decode to heights and ImageBitmaps', { skip, timeout: 120_000 }, async () => {
  assert.ok(!missing, `missing ${missing}`);
  const wasmPath = process.env.VTZ_WASM ?? path.join(root, 'web/dist/vtz.wasm');
  await init(new URL(`file://${path.resolve(wasmPath)}`));
  const server = await serve();
  const base = `http://127.0.0.1:${server.address().port}`;
  const browser = await chromium.launch({ executablePath: chromePath, headless: true, args: ['--no-sandbox'] });
  try {
    const page = await browser.newPage();
    const errors = [];
    page.on('pageerror', (e) => errors.push(String(e)));
    await page.goto(`${base}/blank.html`);
    const wasmUrl = process.env.VTZ_WASM ? null : `${base}/web/dist/vtz.wasm`;
    const wasmBytes = wasmUrl ? null : [...fs.readFileSync(wasmPath)];
    const got = await page.evaluate(
      async ({ base, names, rgbaOpts, wasmUrl, wasmBytes }) => {
        const { VtzDecoder } = await import(`${base}/web/src/client.js`);
        const wasm = wasmUrl ?? (await WebAssembly.compile(new Uint8Array(wasmBytes)));
        const dec = new VtzDecoder({ wasmUrl: wasm, workers: 2 });
        const out = [];
        for (const n of names) {
          const bytes = await (await fetch(`${base}/tests/golden/${n}.vtz`)).arrayBuffer();
          const d = await dec.decode(bytes);
          const bitmap = await dec.decodeBitmap(bytes, rgbaOpts);
          const canvas = new OffscreenCanvas(bitmap.width, bitmap.height);
          const ctx = canvas.getContext('2d');
          ctx.drawImage(bitmap, 0, 0);
          const px = ctx.getImageData(0, 0, bitmap.width, bitmap.height).data;
          out.push({ n, width: d.width, height: d.height, heights: [...new Uint8Array(d.heights.buffer)], rgba: [...px] });
        }
        let error = null;
        try {
          await dec.decode(new Uint8Array(10));
        } catch (e) {
          error = `${e.name}: ${e.message}`;
        }
        await dec.terminate();
        return { out, error };
      },
      { base, names, rgbaOpts, wasmUrl, wasmBytes },
    );
    assert.deepEqual(errors, []);
    for (const g of got.out) {
      const bytes = fs.readFileSync(path.join(root, `tests/golden/${g.n}.vtz`));
      const want = decode(bytes);
      assert.equal(g.width, want.width, g.n);
      assert.ok(Buffer.from(g.heights).equals(Buffer.from(want.heights.buffer)), `${g.n}: heights differ`);
      assert.ok(Buffer.from(g.rgba).equals(Buffer.from(toRGBA(want, rgbaOpts))), `${g.n}: bitmap pixels differ`);
    }
    assert.match(got.error ?? '', /^VtzError: /);
  } finally {
    await browser.close();
    server.close();
  }
});
