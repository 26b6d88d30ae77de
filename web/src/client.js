// A pool of decoding workers (worker.js): the page compiles vtz.wasm once and sends the
// compiled module to each worker. Every method takes the bytes of one `.vtz` stream (a web
// map tile, say) and an optional AbortSignal, so a MapLibre `addProtocol` handler can call
// `decodeBitmap(bytes, {...encoding, signal: abortController.signal})` directly.
import { demEncoding } from './vtz.js';

/**
 * @typedef {object} DecoderOptions
 * @property {string | URL} [workerUrl] worker.js (default: next to this file).
 * @property {string | URL | WebAssembly.Module} [wasmUrl] vtz.wasm (default: ../dist/vtz.wasm).
 * @property {number} [workers] Pool size (default: hardwareConcurrency − 1, 1 to 4).
 */

/**
 * @typedef {import('./vtz.js').RGBAOptions & {signal?: AbortSignal, transfer?: boolean}} CallOptions
 * `transfer`: hand the input's buffer to the worker instead of copying it (the caller's
 * array is then detached).
 */

/** Worker-like wrapper: the browser's Worker, or Node's worker_threads. */
async function spawn(/** @type {URL} */ url) {
  if (typeof Worker !== 'undefined') {
    const w = new Worker(url, { type: 'module' });
    return {
      on: (/** @type {(d: any) => void} */ f) => w.addEventListener('message', (e) => f(e.data)),
      onError: (/** @type {(e: any) => void} */ f) => w.addEventListener('error', f),
      post: (/** @type {any} */ m, /** @type {Transferable[]} */ t = []) => w.postMessage(m, t),
      terminate: () => w.terminate(),
    };
  }
  const { Worker: NodeWorker } = await import('node:worker_threads');
  const w = new NodeWorker(url);
  return {
    on: (/** @type {(d: any) => void} */ f) => w.on('message', f),
    onError: (/** @type {(e: any) => void} */ f) => w.on('error', f),
    post: (/** @type {any} */ m, /** @type {any[]} */ t = []) => w.postMessage(m, t),
    terminate: () => w.terminate(),
  };
}

export class VtzDecoder {
  /** @param {DecoderOptions} [opts] */
  constructor(opts = {}) {
    const workerUrl = new URL(opts.workerUrl ?? './worker.js', import.meta.url);
    const wasm = opts.wasmUrl ?? new URL('../dist/vtz.wasm', import.meta.url);
    const n = opts.workers ?? Math.min(4, Math.max(1, (globalThis.navigator?.hardwareConcurrency ?? 2) - 1));
    /** @type {Map<number, {resolve: Function, reject: Function, slot: any}>} */
    this.pending = new Map();
    this.nextId = 1;
    this.ready = (async () => {
      const module = wasm instanceof WebAssembly.Module ? wasm : await compileOnce(wasm);
      return Promise.all(Array.from({ length: n }, () => this.#start(workerUrl, module)));
    })();
  }

  /** @param {URL} url @param {WebAssembly.Module} module */
  async #start(url, module) {
    const w = await spawn(url);
    const slot = { w, busy: 0 };
    await new Promise((resolve, reject) => {
      w.onError(reject);
      w.on((/** @type {any} */ d) => {
        if (d.type === 'ready') return d.error ? reject(new Error(d.error)) : resolve(undefined);
        const p = this.pending.get(d.id);
        if (!p) return; // aborted
        this.pending.delete(d.id);
        slot.busy--;
        if (d.error !== undefined) {
          const e = new Error(d.error);
          e.name = d.name ?? 'Error';
          p.reject(e);
        } else {
          p.resolve(d);
        }
      });
      w.post({ type: 'init', wasm: module });
    });
    return slot;
  }

  /**
   * @param {ArrayBuffer | ArrayBufferView} bytes
   * @param {any} req
   * @param {CallOptions} opts
   */
  async #run(bytes, req, opts) {
    const slots = await this.ready;
    opts.signal?.throwIfAborted();
    const slot = slots.reduce((a, b) => (b.busy < a.busy ? b : a));
    const id = this.nextId++;
    let buf = bytes instanceof ArrayBuffer ? bytes : /** @type {ArrayBufferView} */ (bytes);
    const transfer = [];
    if (opts.transfer) {
      transfer.push(buf instanceof ArrayBuffer ? buf : buf.buffer);
    } else {
      buf = buf instanceof ArrayBuffer ? buf.slice(0) : new Uint8Array(buf.buffer, buf.byteOffset, buf.byteLength).slice();
      transfer.push(buf instanceof ArrayBuffer ? buf : buf.buffer);
    }
    return new Promise((resolve, reject) => {
      this.pending.set(id, { resolve, reject, slot });
      slot.busy++;
      opts.signal?.addEventListener(
        'abort',
        () => {
          if (this.pending.delete(id)) {
            slot.busy--;
            reject(opts.signal?.reason);
          }
        },
        { once: true },
      );
      slot.w.post({ id, bytes: buf, ...req }, transfer);
    });
  }

  /**
   * Decode to heights (nodata NaN).
   * @param {ArrayBuffer | ArrayBufferView} bytes
   * @param {CallOptions} [opts]
   * @returns {Promise<import('./vtz.js').Decoded>}
   */
  async decode(bytes, opts = {}) {
    const { width, height, heights, nodata } = await this.#run(bytes, { output: 'heights' }, opts);
    return { width, height, heights, nodata };
  }

  /**
   * Decode and pack into RGBA8 for a raster-dem source (see toRGBA in vtz.js).
   * @param {ArrayBuffer | ArrayBufferView} bytes
   * @param {CallOptions} [opts]
   * @returns {Promise<{width: number, height: number, rgba: Uint8ClampedArray}>}
   */
  async decodeRGBA(bytes, opts = {}) {
    const { width, height, rgba } = await this.#run(bytes, { output: 'rgba', rgba: rgbaOpts(opts) }, opts);
    return { width, height, rgba };
  }

  /**
   * Decode, pack into RGBA8 and make an ImageBitmap in the worker (browsers).
   * @param {ArrayBuffer | ArrayBufferView} bytes
   * @param {CallOptions} [opts]
   * @returns {Promise<ImageBitmap>}
   */
  async decodeBitmap(bytes, opts = {}) {
    return (await this.#run(bytes, { output: 'bitmap', rgba: rgbaOpts(opts) }, opts)).bitmap;
  }

  /** The raster-dem source properties for `opts` (see demEncoding in vtz.js). */
  demEncoding(/** @type {import('./vtz.js').RGBAOptions} */ opts = {}) {
    return demEncoding(opts);
  }

  /** Stop the workers; pending calls reject. */
  async terminate() {
    const slots = await this.ready.catch(() => []);
    for (const [id, p] of this.pending) {
      this.pending.delete(id);
      p.reject(new Error('vtz: decoder terminated'));
    }
    await Promise.all(slots.map((s) => s.w.terminate()));
  }
}

/** @param {CallOptions} o */
function rgbaOpts({ encoding, quantum, baseShift, fill }) {
  return { encoding, quantum, baseShift, fill };
}

/** @param {string | URL} url @returns {Promise<WebAssembly.Module>} */
async function compileOnce(url) {
  const u = new URL(url, typeof location !== 'undefined' ? location.href : import.meta.url);
  if (u.protocol === 'file:') {
    const { readFile } = await import('node:fs/promises');
    return WebAssembly.compile(await readFile(u));
  }
  const res = await fetch(u);
  if (!res.ok) throw new Error(`vtz: cannot load ${u}: HTTP ${res.status}`);
  return res.headers.get('content-type') === 'application/wasm' && WebAssembly.compileStreaming
    ? WebAssembly.compileStreaming(res)
    : WebAssembly.compile(await res.arrayBuffer());
}
