// Decode timing in Node: node web/bench.mjs [--wasm PATH] [--reps N] FILE.vtz...
// Prints, per file, the size and the first, minimum and median decode (to f32 heights) in ms,
// and the time of toRGBA (terrarium) on the decode.
import fs from 'node:fs';
import { init, decode, toRGBA } from './src/vtz.js';

const args = process.argv.slice(2);
let wasm = new URL('./dist/vtz.wasm', import.meta.url);
let reps = 20;
const files = [];
for (let i = 0; i < args.length; i++) {
  if (args[i] === '--wasm') wasm = new URL(args[++i], `file://${process.cwd()}/`);
  else if (args[i] === '--reps') reps = Number(args[++i]);
  else files.push(args[i]);
}
const t0 = performance.now();
await init(wasm);
console.log(`init (compile + instantiate): ${(performance.now() - t0).toFixed(1)} ms`);
for (const f of files) {
  const bytes = fs.readFileSync(f);
  const times = [];
  let d;
  for (let k = 0; k < reps; k++) {
    const t = performance.now();
    d = decode(bytes);
    times.push(performance.now() - t);
  }
  const first = times[0];
  const sorted = times.slice(1).sort((a, b) => a - b);
  const t = performance.now();
  toRGBA(d);
  const rgba = performance.now() - t;
  console.log(
    `${f}: ${d.width}x${d.height}, ${bytes.length} B; decode first ${first.toFixed(1)} ms, ` +
      `min ${sorted[0].toFixed(2)} ms, median ${sorted[sorted.length >> 1].toFixed(2)} ms; toRGBA ${rgba.toFixed(2)} ms`,
  );
}
