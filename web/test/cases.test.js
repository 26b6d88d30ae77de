// Bit-exact against the native decoder: VTZ_WEB_CASES=DIR holds X.vtz + X.f32 pairs from
// `vtz encode` and `vtz decode -o X.f32` (web/test/make_cases.sh); X.f32 holds nodata as the
// header's nodata value, which decode(..., {nodata: 'value'}) gives too.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import fs from 'node:fs';
import { pathToFileURL } from 'node:url';
import path from 'node:path';
import { init, decode } from '../src/vtz.js';

const dir = process.env.VTZ_WEB_CASES;

test('native cases: VTZ_WEB_CASES holds .vtz + .f32 pairs', { skip: dir ? false : 'VTZ_WEB_CASES is not set' }, async (t) => {
  await init(process.env.VTZ_WASM ? pathToFileURL(path.resolve(process.env.VTZ_WASM)) : new URL('../dist/vtz.wasm', import.meta.url));
  const names = fs.readdirSync(dir).filter((f) => f.endsWith('.vtz')).map((f) => f.slice(0, -4));
  const pairs = names.filter((n) => fs.existsSync(path.join(dir, n + '.f32'))).sort();
  assert.ok(pairs.length > 0, `no .vtz + .f32 pairs in ${dir}`);
  for (const name of pairs) {
    await t.test(name, () => {
      const d = decode(fs.readFileSync(path.join(dir, name + '.vtz')), { nodata: 'value' });
      const expected = fs.readFileSync(path.join(dir, name + '.f32'));
      assert.equal(d.width * d.height * 4, expected.length, `${name}: size`);
      assert.ok(Buffer.from(d.heights.buffer).equals(expected), `${name}: samples differ from the native decoder's`);
    });
  }
});
