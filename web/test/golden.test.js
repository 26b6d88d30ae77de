// Every golden file of the Rust tests (tests/golden/) decodes in the wasm decoder to its
// expected samples, bit for bit: `.expected.f32` compared byte for byte, `.expected.crc32`
// (the banded files) by the CRC-32 of the same f32 bytes; the point set is refused clearly.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import { pathToFileURL } from 'node:url';
import path from 'node:path';
import { init, decode, VtzError } from '../src/vtz.js';

const dir = new URL('../../tests/golden/', import.meta.url);
await init(process.env.VTZ_WASM ? pathToFileURL(path.resolve(process.env.VTZ_WASM)) : new URL('../dist/vtz.wasm', import.meta.url));

const names = fs.readdirSync(dir).filter((f) => f.endsWith('.vtz')).map((f) => f.slice(0, -4)).sort();
const has = (name, ext) => fs.existsSync(new URL(name + ext, dir));

/** CRC-32 (IEEE, as crc32fast) */
function crc32(/** @type {Uint8Array} */ b) {
  let c = ~0;
  for (let i = 0; i < b.length; i++) {
    c ^= b[i];
    for (let k = 0; k < 8; k++) c = (c >>> 1) ^ (0xedb88320 & -(c & 1));
  }
  return (~c >>> 0).toString(16).padStart(8, '0');
}

const bytesOf = (/** @type {Float32Array} */ h) => Buffer.from(h.buffer, h.byteOffset, h.byteLength);

test('the golden directory has raster files with expected samples', () => {
  assert.ok(names.filter((n) => has(n, '.expected.f32')).length >= 20, names.join(' '));
});

for (const name of names) {
  const vtz = fs.readFileSync(new URL(name + '.vtz', dir));
  if (has(name, '.expected.f32')) {
    test(`golden ${name}: bit-identical to .expected.f32`, () => {
      const expected = fs.readFileSync(new URL(name + '.expected.f32', dir));
      const d = decode(vtz, { nodata: 'value' });
      assert.equal(d.width * d.height * 4, expected.length);
      assert.ok(bytesOf(d.heights).equals(expected), `${name}: samples differ`);
      // The default (nodata NaN) differs only where the expected sample is the nodata value.
      const nan = decode(vtz).heights;
      const exp = new Float32Array(expected.buffer.slice(expected.byteOffset, expected.byteOffset + expected.length));
      for (let i = 0; i < exp.length; i++) {
        if (Number.isNaN(nan[i])) assert.equal(exp[i], Math.fround(d.nodata), `${name} sample ${i}`);
        else assert.ok(Object.is(nan[i], exp[i]), `${name} sample ${i}`);
      }
    });
  } else if (has(name, '.expected.crc32')) {
    test(`golden ${name}: CRC-32 of the f32 samples matches .expected.crc32`, () => {
      const expected = fs.readFileSync(new URL(name + '.expected.crc32', dir), 'utf8').trim();
      assert.equal(crc32(bytesOf(decode(vtz, { nodata: 'value' }).heights)), expected);
    });
  } else {
    test(`golden ${name}: not a raster, refused with a clear error`, () => {
      assert.throws(() => decode(vtz), (e) => {
        assert.ok(e instanceof VtzError, String(e));
        assert.match(e.message, /point/i);
        return true;
      });
    });
  }
}
