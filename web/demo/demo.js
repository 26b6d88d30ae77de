// The demo: 3D terrain and hillshade in MapLibre GL JS from a `vtz web` archive, decoded in
// the browser (web/src). Query parameters:
//   vtz=URL          the archive (default /archives/terrain.pmtiles)
//   terrarium=URL    instead, a Terrarium/Terrain-RGB PMTiles (`vtz web --format terrarium-png`)
//                    through the pmtiles package's own protocol, for comparison
//   mode=3d|hillshade  3D terrain pitched 60° with hillshade (default), or hillshade only, flat
//   center=LON,LAT  zoom=Z  bearing=B  pitch=P   the view (default: the archive's centre)
// The page sets window.ready when the map is idle with every tile loaded, window.failed on
// an error, and window.stats (tiles, decode time, first render, heights sampled on the
// terrain) for tests/js/maplibre.mjs.
import * as maplibregl from 'maplibre-gl';
import { PMTiles, Protocol } from 'pmtiles';
import { VtzProtocol } from '../src/maplibre.js';

const t0 = performance.now();
const q = new URLSearchParams(location.search);
const abs = (/** @type {string} */ u) => new URL(u, location.href).href;
const mode = q.get('mode') ?? '3d';
window.errors = [];
const info = document.getElementById('info');

const vtz = new VtzProtocol({ PMTiles, decoderOptions: { wasmUrl: new URL('../dist/vtz.wasm', import.meta.url) } });
maplibregl.addProtocol('vtz', vtz.tile);
const pm = new Protocol();
maplibregl.addProtocol('pmtiles', pm.tile);

async function demSource() {
  const terrarium = q.get('terrarium');
  if (terrarium) {
    const url = abs(terrarium);
    const p = new PMTiles(url);
    pm.add(p);
    const [h, meta] = await Promise.all([p.getHeader(), p.getMetadata()]);
    return {
      header: h,
      source: {
        type: 'raster-dem',
        tiles: [`pmtiles://${url}/{z}/{x}/{y}`],
        tileSize: meta.tileSize ?? 512,
        minzoom: h.minZoom,
        maxzoom: h.maxZoom,
        bounds: [h.minLon, h.minLat, h.maxLon, h.maxLat],
        encoding: meta.encoding,
      },
    };
  }
  const url = abs(q.get('vtz') ?? '/archives/terrain.pmtiles');
  return { header: await vtz.archive(url).getHeader(), source: await vtz.source(url) };
}

try {
  const { header, source } = await demSource();
  const center = q.get('center')?.split(',').map(Number) ?? [header.centerLon, header.centerLat];
  const flat = mode === 'hillshade';
  const map = new maplibregl.Map({
    container: 'map',
    center,
    zoom: Number(q.get('zoom') ?? header.centerZoom),
    pitch: Number(q.get('pitch') ?? (flat ? 0 : 60)),
    bearing: Number(q.get('bearing') ?? (flat ? 0 : -20)),
    maxPitch: 85,
    fadeDuration: 0,
    attributionControl: false,
    canvasContextAttributes: { preserveDrawingBuffer: true },
    style: {
      version: 8,
      sources: { dem: source, hillshade: source },
      layers: [
        { id: 'background', type: 'background', paint: { 'background-color': '#d8e4ec' } },
        {
          id: 'hillshade', type: 'hillshade', source: 'hillshade',
          paint: { 'hillshade-exaggeration': 0.8, 'hillshade-shadow-color': '#3a3a52', 'hillshade-highlight-color': '#ffffff', 'hillshade-accent-color': '#5c6b54' },
        },
      ],
      ...(flat ? {} : { terrain: { source: 'dem', exaggeration: 1.5 } }),
      sky: {},
    },
  });
  window.map = map;
  map.on('error', (e) => window.errors.push(`map error: ${e.error?.message ?? e.error ?? e}`));
  // Every tile of both sources loaded (polled: 'idle' may have fired already), then one more
  // frame drawn: the first full render.
  await new Promise((ok) => {
    const check = () => (map.loaded() && map.areTilesLoaded() ? ok() : setTimeout(check, 100));
    check();
  });
  await new Promise((ok) => {
    map.once('idle', ok);
    map.triggerRepaint();
  });
  const firstRenderMs = performance.now() - t0;
  // Heights on the terrain at a 5 × 5 grid of the view (3D only).
  const heights = [];
  if (!flat) {
    const b = map.getBounds();
    for (let i = 1; i <= 5; i++) {
      for (let j = 1; j <= 5; j++) {
        const lon = b.getWest() + ((b.getEast() - b.getWest()) * i) / 6;
        const lat = b.getSouth() + ((b.getNorth() - b.getSouth()) * j) / 6;
        heights.push([lon, lat, map.queryTerrainElevation([lon, lat]) ?? null]);
      }
    }
  }
  // The tile edges of the source's zoom on screen (for the seam check of a flat view).
  const z = Math.min(source.maxzoom, Math.max(0, Math.floor(map.getZoom() + Math.log2(512 / source.tileSize))));
  const n = 2 ** z;
  const c = maplibregl.MercatorCoordinate.fromLngLat(map.getCenter());
  const edges = { z, xs: [], ys: [] };
  for (let k = Math.floor(c.x * n) - 4; k <= Math.floor(c.x * n) + 5; k++) {
    edges.xs.push(map.project(new maplibregl.MercatorCoordinate(k / n, c.y).toLngLat()).x);
  }
  for (let k = Math.floor(c.y * n) - 4; k <= Math.floor(c.y * n) + 5; k++) {
    edges.ys.push(map.project(new maplibregl.MercatorCoordinate(c.x, k / n).toLngLat()).y);
  }
  window.stats = { vtz: vtz.stats, firstRenderMs, heights, edges, zoom: map.getZoom(), source: q.get('terrarium') ? 'terrarium' : 'vtz' };
  const s = vtz.stats;
  info.textContent = q.get('terrarium')
    ? `Terrarium tiles; first render ${firstRenderMs.toFixed(0)} ms`
    : `${s.tiles} vtz tiles, ${(s.bytes / 1024).toFixed(0)} KB, ${(s.decodeMs / Math.max(1, s.tiles)).toFixed(1)} ms/tile from request to bitmap; first render ${firstRenderMs.toFixed(0)} ms`;
  window.ready = true;
} catch (e) {
  window.errors.push(String(e?.stack ?? e));
  window.failed = String(e?.message ?? e);
  info.textContent = `failed: ${window.failed}`;
}
