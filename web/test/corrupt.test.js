// Corrupt input throws a VtzError (the Rust decoder's message), never a silent trap or a
// wrong raster without an error; the module keeps working afterwards.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import { pathToFileURL } from 'node:url';
import path from 'node:path';
import { init, decode, VtzError } from '../src/vtz.js';

const dir = new URL('../../tests/golden/', import.meta.url);
await init(process.env.VTZ_WASM ? pathToFileURL(path.resolve(process.env.VTZ_WASM)) : new URL('../dist/vtz.wasm', import.meta.url));

const files = ['v1_kauai_crop_residual', 'v1_kauai_crop_residual_lanes', 'v4_kauai_tiles', 'v5_kauai_tiles', 'v1_kauai_crop_haar'];

for (const name of files) {
  const good = new Uint8Array(fs.readFileSync(new URL(name + '.vtz', dir)));
  const reference = decode(good).heights;

  test(`${name}: every truncated prefix is refused`, () => {
    const step = Math.max(1, Math.floor(good.length / 200));
    for (let n = 0; n < good.length; n += n < 64 ? 1 : step) {
      assert.throws(() => decode(good.subarray(0, n)), VtzError, `prefix of ${n} bytes`);
    }
  });

  test(`${name}: flipped bytes are refused or decode to a raster of the same size`, () => {
    let s = 7;
    let refused = 0;
    for (let k = 0; k < 150; k++) {
      s = (s * 1103515245 + 12345) >>> 0;
      const bad = good.slice();
      const i = s % bad.length;
      bad[i] ^= 1 << ((s >>> 16) & 7);
      try {
        const d = decode(bad);
        // The container's checksums catch most flips; one that slips through must still
        // give a whole raster.
        assert.equal(d.heights.length, reference.length, `flip at ${i}`);
      } catch (e) {
        assert.ok(e instanceof VtzError, `flip at ${i}: ${e}`);
        assert.ok(e.message.length > 0);
        refused++;
      }
    }
    assert.ok(refused > 0);
    // Still decodes correctly after all that.
    assert.deepEqual(decode(good).heights, reference);
  });
}

test('not a vtz stream at all', () => {
  assert.throws(() => decode(new TextEncoder().encode('GIF89a, certainly not vtz')), VtzError);
  assert.throws(() => decode(new Uint8Array(0)), VtzError);
  assert.throws(() => decode('a string'), TypeError);
});
