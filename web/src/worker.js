// A module worker that decodes `.vtz` streams off the main thread (a browser Web Worker, or
// a Node worker_threads Worker). Messages:
//   {type: 'init', wasm}                 wasm: what init() takes (a compiled module is best);
//                                        answered {type: 'ready'} or {type: 'ready', error}
//   {id, bytes, output, rgba}            output: 'heights' (default), 'rgba' or 'bitmap';
//                                        rgba: RGBAOptions (see vtz.js) for 'rgba'/'bitmap'
// answered {id, width, height, heights | rgba | bitmap} or {id, error}; the result's buffer
// (or the ImageBitmap) is transferred. 'bitmap' needs createImageBitmap (browsers).
import { init, decode, decodeRGBA } from './vtz.js';

/** @type {{on: (f: (data: any) => void) => void, post: (msg: any, transfer?: Transferable[]) => void}} */
const port = await (async () => {
  if (typeof self !== 'undefined' && typeof self.postMessage === 'function') {
    return {
      on: (f) => self.addEventListener('message', (e) => f(/** @type {MessageEvent} */ (e).data)),
      post: (msg, transfer = []) => self.postMessage(msg, { transfer }),
    };
  }
  const { parentPort } = await import('node:worker_threads');
  if (!parentPort) throw new Error('vtz worker.js: not running in a worker');
  return { on: (f) => parentPort.on('message', f), post: (msg, transfer = []) => parentPort.postMessage(msg, transfer) };
})();

/** @type {Promise<unknown> | null} */
let ready = null;

port.on(async (msg) => {
  if (msg.type === 'init') {
    ready = init(msg.wasm);
    try {
      await ready;
      port.post({ type: 'ready' });
    } catch (e) {
      port.post({ type: 'ready', error: String(/** @type {Error} */ (e).message ?? e) });
    }
    return;
  }
  const { id } = msg;
  try {
    if (!ready) throw new Error('vtz worker: no init message');
    await ready;
    const output = msg.output ?? 'heights';
    if (output === 'heights') {
      const d = decode(msg.bytes);
      port.post({ id, width: d.width, height: d.height, nodata: d.nodata, heights: d.heights }, [d.heights.buffer]);
    } else if (output === 'rgba' || output === 'bitmap') {
      const { width, height, rgba } = decodeRGBA(msg.bytes, msg.rgba ?? {});
      if (output === 'rgba') {
        port.post({ id, width, height, rgba }, [rgba.buffer]);
      } else {
        const bitmap = await createImageBitmap(new ImageData(rgba, width, height), {
          premultiplyAlpha: 'none',
          colorSpaceConversion: 'none',
        });
        port.post({ id, width, height, bitmap }, [bitmap]);
      }
    } else {
      throw new Error(`vtz worker: unknown output ${output}`);
    }
  } catch (e) {
    port.post({ id, error: String(/** @type {Error} */ (e).message ?? e), name: /** @type {Error} */ (e).name });
  }
});
