// MapLibre GL JS (≥ 4, Promise-based addProtocol) raster-dem tiles from a `vtz web`
// archive: a PMTiles file of `.vtz` tiles, read by range requests with the `pmtiles`
// package, each tile decoded in a worker (client.js) into the RGBA MapLibre unpacks.
//
//   import * as maplibregl from 'maplibre-gl';
//   import { PMTiles } from 'pmtiles';
//   import { VtzProtocol } from '@vtz/web/maplibre';
//   const vtz = new VtzProtocol({ PMTiles });
//   maplibregl.addProtocol('vtz', vtz.tile);
//   const dem = await vtz.source('https://example.com/terrain.pmtiles');
//   map.addSource('dem', dem);               // terrain: map.setTerrain({source: 'dem'})
//   map.addSource('hillshade', dem);         // MapLibre wants a second source for hillshade
//
// Tile URLs are `vtz://ARCHIVE-URL/{z}/{x}/{y}` (source() writes them). A tile the archive
// lacks answers `{data: null}` (no DEM there). The RGBA is Terrarium by default (heights to
// 1/512 m on top of the archive's bound); `encoding: 'custom'` with `quantum`/`baseShift`
// gives MapLibre's custom factors instead. Nodata pixels become `fill` metres (default 0):
// MapLibre's raster-dem has no nodata.
import { VtzDecoder } from './client.js';
import { demEncoding } from './vtz.js';

const TILE = /^vtz:\/\/(.+)\/(\d+)\/(\d+)\/(\d+)$/;

export class VtzProtocol {
  /**
   * @param {object} opts
   * @param {new (url: string) => any} opts.PMTiles The `PMTiles` class of the `pmtiles` package.
   * @param {VtzDecoder} [opts.decoder] A decoder pool to share (default: a new one).
   * @param {import('./client.js').DecoderOptions} [opts.decoderOptions] For the new pool.
   * @param {import('./vtz.js').RGBAOptions} [opts.rgba] Packing: {encoding, quantum, baseShift, fill}.
   */
  constructor({ PMTiles, decoder, decoderOptions, rgba = {} }) {
    if (typeof PMTiles !== 'function') throw new TypeError('vtz: VtzProtocol needs the PMTiles class of the pmtiles package');
    this.PMTiles = PMTiles;
    this.decoder = decoder ?? new VtzDecoder(decoderOptions);
    this.rgba = rgba;
    /** @type {Map<string, any>} */
    this.archives = new Map();
    /** Tiles answered, empty, failed (for pages and tests). */
    this.stats = { tiles: 0, empty: 0, errors: 0, bytes: 0, decodeMs: 0 };
    this.tile = this.tile.bind(this);
  }

  /** The PMTiles reader of `url` (one per URL, so its directory cache is shared). */
  archive(/** @type {string} */ url) {
    let a = this.archives.get(url);
    if (!a) {
      a = new this.PMTiles(url);
      this.archives.set(url, a);
    }
    return a;
  }

  /**
   * The raster-dem source of a `vtz web` archive: tiles, tileSize, zooms and bounds from its
   * header and metadata, and the encoding that unpacks this protocol's RGBA.
   * @param {string} url
   * @param {object} [extra] More source properties (attribution, …).
   */
  async source(url, extra = {}) {
    const a = this.archive(url);
    const [header, meta] = await Promise.all([a.getHeader(), a.getMetadata()]);
    if (meta?.encoding !== 'vtz') {
      throw new Error(`vtz: ${url} is not a vtz web archive (metadata encoding ${JSON.stringify(meta?.encoding)})`);
    }
    return {
      type: 'raster-dem',
      tiles: [`vtz://${url}/{z}/{x}/{y}`],
      tileSize: meta.tileSize ?? 512,
      minzoom: header.minZoom,
      maxzoom: header.maxZoom,
      bounds: [header.minLon, header.minLat, header.maxLon, header.maxLat],
      ...demEncoding(this.rgba),
      ...extra,
    };
  }

  /**
   * The addProtocol handler: `maplibregl.addProtocol('vtz', protocol.tile)`.
   * @param {{url: string}} params
   * @param {AbortController} abortController
   */
  async tile(params, abortController) {
    const m = TILE.exec(params.url);
    if (!m) throw new Error(`vtz: not a vtz tile URL: ${params.url}`);
    const [, url, z, x, y] = m;
    const signal = abortController?.signal;
    try {
      const r = await this.archive(url).getZxy(Number(z), Number(x), Number(y), signal);
      if (!r) {
        this.stats.empty++;
        return { data: null };
      }
      const t0 = performance.now();
      const bitmap = await this.decoder.decodeBitmap(new Uint8Array(r.data), { ...this.rgba, signal });
      this.stats.decodeMs += performance.now() - t0;
      this.stats.tiles++;
      this.stats.bytes += r.data.byteLength;
      return { data: bitmap, cacheControl: r.cacheControl, expires: r.expires };
    } catch (e) {
      if (!signal?.aborted) this.stats.errors++;
      throw e;
    }
  }
}
