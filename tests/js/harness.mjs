// What the browser checks share: a static server on 127.0.0.1 that answers byte ranges
// (PMTiles readers ask for them), Debian's Chromium headless through playwright-core with
// software WebGL and no host but this one, a page watcher, and the blank-picture measure.
import { existsSync, readFileSync } from 'node:fs';
import { chromium } from 'playwright-core';
import pngjs from 'pngjs';

const { PNG } = pngjs;
// The static server with byte ranges is the demo's own (web/demo/server.mjs).
export { TYPES, serve } from '../../web/demo/server.mjs';
export const MIN_COLOURS = 64;
export const MIN_LUMA_STD = 15;


/** Distinct RGB colours and the standard deviation of Rec. 709 luminance (0–255) of a PNG. */
export function measure(file) {
  const { data, width, height } = PNG.sync.read(readFileSync(file));
  const colours = new Set();
  let sum = 0;
  let sum2 = 0;
  const n = width * height;
  for (let i = 0; i < n; i++) {
    const r = data[4 * i];
    const g = data[4 * i + 1];
    const b = data[4 * i + 2];
    colours.add((r << 16) | (g << 8) | b);
    const y = 0.2126 * r + 0.7152 * g + 0.0722 * b;
    sum += y;
    sum2 += y * y;
  }
  const mean = sum / n;
  const std = Math.sqrt(Math.max(0, sum2 / n - mean * mean));
  return { width, height, colours: colours.size, lumaMean: mean, lumaStd: std };
}
export const describe = (m) => `${m.width}×${m.height}, ${m.colours} colours, luminance mean ${m.lumaMean.toFixed(1)} std ${m.lumaStd.toFixed(1)}`;
export const blank = (m) => m.colours < MIN_COLOURS || m.lumaStd < MIN_LUMA_STD;

/** Debian's Chromium (or $CHROMIUM), headless, WebGL on the CPU, no host but 127.0.0.1. */
export async function launch() {
  const executablePath = process.env.CHROMIUM ?? '/usr/bin/chromium';
  if (!existsSync(executablePath)) throw new Error(`${executablePath} not found (apt-get install chromium)`);
  const args = [
    '--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
    '--disable-background-networking', '--disable-component-update', '--disable-sync',
    // WebGL on the CPU.
    '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist',
    // Nothing but this machine: every other host name fails to resolve.
    '--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1',
  ];
  return chromium.launch({ executablePath, headless: true, args });
}

/**
 * Watch a page: console errors printed, page errors, requests off `origin`, failed requests
 * and HTTP errors collected into the returned array.
 */
export function watch(page, origin, name) {
  const problems = [];
  page.on('console', (msg) => {
    if ((msg.type() === 'error' || msg.type() === 'warning') && !msg.text().includes('GL Driver Message')) {
      console.log(`  [${name} console.${msg.type()}] ${msg.text()}`);
    }
  });
  page.on('pageerror', (e) => problems.push(`JavaScript error: ${e.message}`));
  page.on('request', (r) => {
    const u = r.url();
    if (!u.startsWith(origin) && !u.startsWith('data:') && !u.startsWith('blob:')) problems.push(`asked for ${u}, off this machine`);
  });
  const answered = new Set();
  page.on('response', (r) => {
    if (r.status() >= 400) problems.push(`HTTP ${r.status()} ${r.url()}`);
    else answered.add(r.url());
  });
  page.on('requestfailed', (r) => {
    const why = r.failure()?.errorText;
    // An answered fetch whose body was read to the end is sometimes reported as aborted,
    // and MapLibre aborts the tiles it no longer needs: neither is a failure.
    if (why === 'net::ERR_ABORTED') return;
    problems.push(`request failed: ${r.url()} (${why})`);
  });
  return problems;
}

/** The WebGL 2 renderer string of a page (SwiftShader in CI). */
export async function renderer(page) {
  return page.evaluate(() => {
    const gl = document.createElement('canvas').getContext('webgl2');
    const ext = gl?.getExtension('WEBGL_debug_renderer_info');
    return gl ? gl.getParameter(ext ? ext.UNMASKED_RENDERER_WEBGL : gl.RENDERER) : 'no WebGL 2';
  });
}
