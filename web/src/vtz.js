// vtz's decoder in the browser, Web Workers and Node: the Rust decoder compiled to
// WebAssembly (web/wasm, built by web/build.sh into dist/vtz.wasm), with this hand-written
// glue over its C ABI (no wasm-bindgen). One module instance per JavaScript realm; every
// function here is synchronous once `init` has resolved.

/**
 * @typedef {object} Decoded
 * @property {number} width Samples per row.
 * @property {number} height Rows (row 0 is the top row).
 * @property {Float32Array} heights Row-major heights; nodata samples are NaN (or the
 *   header's nodata value with `{nodata: 'value'}`).
 * @property {number} nodata The header's nodata value (NaN when it has none).
 */

/**
 * @typedef {object} RGBAOptions
 * @property {'terrarium'|'mapbox'|'custom'} [encoding] Default 'custom' when a quantum or
 *   baseShift is given, else 'terrarium'.
 * @property {number} [quantum] Height step of one code for 'custom' (default 0.1).
 * @property {number} [baseShift] Added to a height before coding, for 'custom'
 *   (default 10000: with quantum 0.1, the Mapbox Terrain-RGB coding).
 * @property {number} [fill] Height packed for nodata samples (default 0).
 */

/** Thrown for a stream the decoder refuses (the message is the Rust decoder's). */
export class VtzError extends Error {
  /** @param {string} message */
  constructor(message) {
    super(message);
    this.name = 'VtzError';
  }
}

/** @type {WebAssembly.Module | null} */
let module = null;
/** @type {any} */
let x = null;

const NODATA_AS_VALUE = 1;
const ENCODINGS = { terrarium: 0, custom: 1 };

/**
 * Load the WebAssembly module. Call once (again to replace it) before the other functions.
 * @param {string | URL | Response | Promise<Response> | ArrayBuffer | ArrayBufferView | WebAssembly.Module} [wasmSource]
 *   Where vtz.wasm is: a URL (http(s): fetched; file: read in Node), a fetch Response, the
 *   bytes, or a compiled module (a worker can be sent the one its page compiled). Default:
 *   ../dist/vtz.wasm next to this file.
 * @returns {Promise<WebAssembly.Module>} The compiled module, to hand to workers.
 */
export async function init(wasmSource = new URL('../dist/vtz.wasm', import.meta.url)) {
  module = await compile(await wasmSource);
  instantiate();
  return module;
}

/** @param {any} src @returns {Promise<WebAssembly.Module>} */
async function compile(src) {
  if (src instanceof WebAssembly.Module) return src;
  if (typeof src === 'string' || src instanceof URL) {
    const url = new URL(src, typeof location !== 'undefined' ? location.href : import.meta.url);
    if (url.protocol === 'file:') {
      const { readFile } = await import('node:fs/promises');
      return WebAssembly.compile(await readFile(url));
    }
    src = await fetch(url);
  }
  if (typeof Response !== 'undefined' && src instanceof Response) {
    if (!src.ok) throw new Error(`vtz: cannot load the wasm module: HTTP ${src.status} ${src.url}`);
    if (WebAssembly.compileStreaming && src.headers.get('content-type') === 'application/wasm') {
      return WebAssembly.compileStreaming(src);
    }
    return WebAssembly.compile(await src.arrayBuffer());
  }
  if (src instanceof ArrayBuffer || ArrayBuffer.isView(src)) return WebAssembly.compile(src);
  throw new TypeError('vtz: init() takes a URL, a Response, the bytes or a WebAssembly.Module');
}

function instantiate() {
  // build.sh removes the wasm-bindgen imports that chrono (through las) pulls in; a module
  // built without binaryen still has them. vtz never calls them: stubs that throw.
  /** @type {Record<string, Record<string, Function>>} */
  const imports = {};
  for (const imp of WebAssembly.Module.imports(/** @type {WebAssembly.Module} */ (module))) {
    if (imp.kind !== 'function') throw new Error(`vtz: unexpected wasm import ${imp.module}.${imp.name}`);
    (imports[imp.module] ??= {})[imp.name] = () => {
      throw new Error(`vtz: wasm import ${imp.module}.${imp.name} called`);
    };
  }
  x = new WebAssembly.Instance(/** @type {WebAssembly.Module} */ (module), imports).exports;
}

/**
 * Call into the module; a trap (a Rust panic) leaves it unusable, so start a fresh one.
 * The module's buffers are released after a success; after an error they stay until the
 * next call replaces them.
 */
function call(/** @type {() => any} */ f) {
  if (!x) throw new Error('vtz: call init() first');
  try {
    return f();
  } catch (e) {
    if (e instanceof WebAssembly.RuntimeError) {
      instantiate();
      throw new VtzError(`vtz: the decoder trapped (${e.message})`);
    }
    throw e;
  }
}

function check(/** @type {number} */ rc) {
  if (rc === 0) return;
  const msg = new TextDecoder().decode(new Uint8Array(x.memory.buffer, x.vtz_error_ptr(), x.vtz_error_len()));
  throw new VtzError(msg);
}

/** @param {ArrayBuffer | ArrayBufferView} bytes @returns {Uint8Array} */
function u8(bytes) {
  if (bytes instanceof Uint8Array) return bytes;
  if (bytes instanceof ArrayBuffer) return new Uint8Array(bytes);
  if (ArrayBuffer.isView(bytes)) return new Uint8Array(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  throw new TypeError('vtz: expected the bytes of a .vtz stream (ArrayBuffer or Uint8Array)');
}

/** Decode into the module's state; returns the flags used. */
function decodeIn(/** @type {ArrayBuffer | ArrayBufferView} */ bytes, /** @type {number} */ flags) {
  const b = u8(bytes);
  const p = x.vtz_alloc(b.length);
  new Uint8Array(x.memory.buffer, p, b.length).set(b);
  check(x.vtz_decode(p, b.length, flags));
}

/**
 * Decode a complete `.vtz` raster stream (any version and method vtz's decoder reads).
 * @param {ArrayBuffer | ArrayBufferView} bytes
 * @param {{nodata?: 'nan' | 'value'}} [opts] Nodata samples as NaN (default) or as the
 *   header's nodata value (as `vtz decode -o X.f32` writes them).
 * @returns {Decoded}
 * @throws {VtzError} on a corrupt, truncated or unsupported stream (a point set, say).
 */
export function decode(bytes, opts = {}) {
  return call(() => {
    decodeIn(bytes, opts.nodata === 'value' ? NODATA_AS_VALUE : 0);
    const heights = new Float32Array(x.memory.buffer, x.vtz_heights_ptr(), x.vtz_heights_len()).slice();
    const d = { width: x.vtz_width(), height: x.vtz_height(), heights, nodata: x.vtz_nodata() };
    x.vtz_free();
    return d;
  });
}

/**
 * Pack heights into RGBA8 (alpha 255) for a MapLibre `raster-dem` source:
 * code = round((h + baseShift) / quantum), clamped to 0…2²⁴−1, R = code >> 16,
 * G = (code >> 8) & 255, B = code & 255; 'terrarium' is quantum 1/256, baseShift 32768
 * (R·256 + G + B/256 − 32768), 'mapbox' quantum 0.1, baseShift 10000. Heights come back
 * within quantum/2 (1/512 m for Terrarium) inside the coded range.
 * @param {ArrayBuffer | ArrayBufferView | Decoded} input A `.vtz` stream or a decode.
 * @param {RGBAOptions} [opts]
 * @returns {Uint8ClampedArray} 4 × width × height bytes.
 */
export function toRGBA(input, opts = {}) {
  return decodeRGBA(input, opts).rgba;
}

/**
 * {@link toRGBA} with the size: what a tile needs for `new ImageData(rgba, width, height)`.
 * @param {ArrayBuffer | ArrayBufferView | Decoded} input
 * @param {RGBAOptions} [opts]
 * @returns {{width: number, height: number, rgba: Uint8ClampedArray}}
 */
export function decodeRGBA(input, opts = {}) {
  const { code, quantum, baseShift } = packing(opts);
  const fill = opts.fill ?? 0;
  return call(() => {
    if (input && typeof input === 'object' && 'heights' in input) {
      const { width, height, heights } = input;
      if (heights.length !== width * height) throw new TypeError('vtz: heights.length is not width × height');
      const p = x.vtz_set_heights(width, height);
      if (p === 0) throw new RangeError('vtz: width × height is too large');
      new Float32Array(x.memory.buffer, p, heights.length).set(heights);
    } else {
      decodeIn(/** @type {ArrayBuffer | ArrayBufferView} */ (input), 0);
    }
    check(x.vtz_to_rgba(code, quantum, baseShift, fill));
    const rgba = new Uint8ClampedArray(x.memory.buffer, x.vtz_rgba_ptr(), x.vtz_rgba_len()).slice();
    const out = { width: x.vtz_width(), height: x.vtz_height(), rgba };
    x.vtz_free();
    return out;
  });
}

/** The encoding: as said, else 'custom' when a quantum or baseShift is given, else 'terrarium'. */
function encodingOf(/** @type {RGBAOptions} */ opts) {
  return opts.encoding ?? (opts.quantum !== undefined || opts.baseShift !== undefined ? 'custom' : 'terrarium');
}

/** @param {RGBAOptions} opts */
function packing(opts) {
  const encoding = encodingOf(opts);
  if (encoding === 'terrarium') return { code: ENCODINGS.terrarium, quantum: 1 / 256, baseShift: 32768 };
  if (encoding === 'mapbox') return { code: ENCODINGS.custom, quantum: 0.1, baseShift: 10000 };
  if (encoding === 'custom') {
    return { code: ENCODINGS.custom, quantum: opts.quantum ?? 0.1, baseShift: opts.baseShift ?? 10000 };
  }
  throw new TypeError(`vtz: unknown encoding ${encoding} (terrarium, mapbox or custom)`);
}

/**
 * The `raster-dem` source properties that decode what {@link toRGBA} packs with `opts`:
 * `{encoding: 'terrarium'}`, `{encoding: 'mapbox'}`, or for 'custom' (the default when a
 * quantum or baseShift is given) MapLibre's factors: redFactor = 65536·q,
 * greenFactor = 256·q, blueFactor = q, baseShift = b.
 * @param {RGBAOptions} [opts]
 * @returns {{encoding: string, redFactor?: number, greenFactor?: number, blueFactor?: number, baseShift?: number}}
 */
export function demEncoding(opts = {}) {
  const encoding = encodingOf(opts);
  if (encoding !== 'custom') {
    packing({ encoding });
    return { encoding };
  }
  const { quantum: q, baseShift } = packing({ ...opts, encoding });
  return { encoding: 'custom', redFactor: 65536 * q, greenFactor: 256 * q, blueFactor: q, baseShift };
}
