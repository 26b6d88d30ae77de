// The worker pool (client.js + worker.js) in Node's worker_threads: same results as the
// in-thread decoder, errors come back as rejections, aborts reject.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import { init, decode, decodeRGBA } from '../src/vtz.js';
import { VtzDecoder } from '../src/client.js';

const wasmUrl = process.env.VTZ_WASM ? new URL(process.env.VTZ_WASM, `file://${process.cwd()}/`) : new URL('../dist/vtz.wasm', import.meta.url);
await init(wasmUrl);
const golden = (n) => fs.readFileSync(new URL(`../../tests/golden/${n}.vtz`, import.meta.url));

test('VtzDecoder: decode, decodeRGBA, errors and abort through two workers', async () => {
  const dec = new VtzDecoder({ wasmUrl, workers: 2 });
  try {
    const names = ['v5_kauai_tiles', 'v1_kauai_crop_residual', 'v4_kauai_tiles_lanes', 'v1_kauai_crop_grid'];
    const got = await Promise.all(names.map((n) => dec.decode(golden(n))));
    for (const [i, n] of names.entries()) {
      const want = decode(golden(n));
      assert.equal(got[i].width, want.width);
      assert.deepEqual(got[i].heights, want.heights, n);
    }
    const opts = { quantum: 0.1, baseShift: 10000, fill: 0 };
    const r = await dec.decodeRGBA(golden('v5_kauai_tiles'), opts);
    assert.deepEqual(r, decodeRGBA(golden('v5_kauai_tiles'), opts));
    await assert.rejects(dec.decode(golden('v3_points')), /point/i);
    await assert.rejects(dec.decode(golden('v5_kauai_tiles').subarray(0, 100)), { name: 'VtzError' });
    const ac = new AbortController();
    const p = dec.decode(golden('v5_kauai_tiles'), { signal: ac.signal });
    ac.abort();
    await assert.rejects(p, { name: 'AbortError' });
    // Still answering after an error and an abort; transfer detaches the caller's buffer.
    const bytes = new Uint8Array(golden('v5_kauai_tiles'));
    const again = await dec.decode(bytes, { transfer: true });
    assert.equal(bytes.byteLength, 0);
    assert.equal(again.width * again.height, again.heights.length);
  } finally {
    await dec.terminate();
  }
});
