// A static server for the demo and the browser tests: files under URL prefixes, from
// 127.0.0.1, answering `Range: bytes=a-b` with 206 (the pmtiles package reads archives by
// ranges and refuses a server that sends whole files).
import { createServer } from 'node:http';
import { createReadStream, existsSync, statSync } from 'node:fs';
import { extname, resolve, sep } from 'node:path';

export const TYPES = {
  '.html': 'text/html; charset=utf-8', '.js': 'text/javascript', '.mjs': 'text/javascript', '.css': 'text/css',
  '.json': 'application/json', '.png': 'image/png', '.jpg': 'image/jpeg', '.svg': 'image/svg+xml',
  '.wasm': 'application/wasm', '.glb': 'model/gltf-binary', '.ktx2': 'image/ktx2',
  '.terrain': 'application/vnd.quantized-mesh', '.woff': 'font/woff', '.woff2': 'font/woff2',
  '.pmtiles': 'application/vnd.pmtiles',
};

/**
 * Serve `roots` ([[url prefix, directory]...]) from 127.0.0.1 on a free port; `Range:
 * bytes=a-b` gets 206 and Content-Range. `onRequest(pathname, file, bytes)` sees every
 * answered request; `port` 0 takes a free one. Resolves to {origin, close, stats}.
 */
export async function serve(roots, onRequest = () => {}, port = 0) {
  const stats = { requests: 0, ranges: 0, bytes: 0, missing: [] };
  const fileFor = (pathname) => {
    for (const [prefix, root] of roots) {
      if (!pathname.startsWith(prefix)) continue;
      const dir = resolve(root);
      const f = resolve(dir, `.${sep}${decodeURIComponent(pathname.slice(prefix.length))}`);
      return f.startsWith(dir + sep) ? f : undefined;
    }
    return undefined;
  };
  const server = createServer((req, res) => {
    stats.requests++;
    const url = new URL(req.url, 'http://localhost');
    const f = fileFor(url.pathname);
    if (!f || !existsSync(f) || !statSync(f).isFile()) {
      if (url.pathname !== '/favicon.ico') stats.missing.push(url.pathname);
      res.writeHead(404, { 'content-type': 'text/plain' });
      res.end('not found');
      return;
    }
    const size = statSync(f).size;
    const headers = {
      'content-type': TYPES[extname(f)] ?? 'application/octet-stream',
      'cache-control': 'no-store',
      'accept-ranges': 'bytes',
    };
    const m = /^bytes=(\d*)-(\d*)$/.exec(req.headers.range ?? '');
    if (m && (m[1] !== '' || m[2] !== '')) {
      let start = m[1] === '' ? size - Number(m[2]) : Number(m[1]);
      let end = m[1] === '' || m[2] === '' ? size - 1 : Math.min(Number(m[2]), size - 1);
      start = Math.max(0, start);
      if (start > end || start >= size) {
        res.writeHead(416, { 'content-range': `bytes */${size}` });
        res.end();
        return;
      }
      stats.ranges++;
      stats.bytes += end - start + 1;
      onRequest(url.pathname, f, end - start + 1);
      res.writeHead(206, { ...headers, 'content-range': `bytes ${start}-${end}/${size}`, 'content-length': end - start + 1 });
      createReadStream(f, { start, end }).pipe(res);
      return;
    }
    stats.bytes += size;
    onRequest(url.pathname, f, size);
    res.writeHead(200, { ...headers, 'content-length': size });
    createReadStream(f).pipe(res);
  });
  await new Promise((ok) => server.listen(port, '127.0.0.1', ok));
  const origin = `http://127.0.0.1:${server.address().port}`;
  return { origin, stats, close: () => new Promise((ok) => server.close(ok)) };
}

