// Serve the demo: `node web/demo/serve.mjs TERRAIN.pmtiles [--terrarium B.pmtiles] [--port N]`
// then open the printed URL. Needs web/dist/vtz.wasm (web/build.sh) and maplibre-gl and
// pmtiles in node_modules (`npm install --prefix web maplibre-gl pmtiles`, or the ones in
// tests/js/node_modules). Serves from 127.0.0.1 only; Ctrl-C stops it.
import { existsSync } from 'node:fs';
import { basename, dirname, join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';
import { serve } from './server.mjs';

const WEB = resolve(dirname(fileURLToPath(import.meta.url)), '..');
const args = process.argv.slice(2);
const usage = (msg) => {
  console.error(`serve: ${msg}\nusage: node web/demo/serve.mjs TERRAIN.pmtiles [--terrarium B.pmtiles] [--port N]`);
  process.exit(2);
};
let archive;
let terrarium;
let port = 0;
for (let i = 0; i < args.length; i++) {
  if (args[i] === '--terrarium') terrarium = args[++i];
  else if (args[i] === '--port') port = Number(args[++i]);
  else if (!archive) archive = args[i];
  else usage(`unexpected ${args[i]}`);
}
if (!archive || !existsSync(archive)) usage(archive ? `${archive}: no such file` : 'no archive given');
if (terrarium && !existsSync(terrarium)) usage(`${terrarium}: no such file`);
if (!existsSync(join(WEB, 'dist/vtz.wasm'))) usage('web/dist/vtz.wasm is missing: run web/build.sh');
const modules = [join(WEB, 'node_modules'), join(WEB, '../tests/js/node_modules')].find((d) => existsSync(join(d, 'maplibre-gl')));
if (!modules) usage('maplibre-gl is not installed: npm install --prefix web maplibre-gl pmtiles');
const roots = [
  ['/web/', WEB],
  ['/node_modules/', modules],
  ['/a/vtz/', dirname(resolve(archive))],
  ...(terrarium ? [['/a/terrarium/', dirname(resolve(terrarium))]] : []),
];
const { origin } = await serve(roots, () => {}, port);
console.log(`3D terrain:  ${origin}/web/demo/index.html?vtz=/a/vtz/${basename(archive)}`);
console.log(`hillshade:   ${origin}/web/demo/index.html?vtz=/a/vtz/${basename(archive)}&mode=hillshade`);
if (terrarium) console.log(`Terrarium:   ${origin}/web/demo/index.html?terrarium=/a/terrarium/${basename(terrarium)}`);
