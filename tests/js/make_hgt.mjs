// Writes an SRTM .hgt tile made from another one, for terrain checks away from sea level:
//
//   node make_hgt.mjs IN.hgt OUT.hgt [--step N] [--scale S] [--offset O]
//
// Every N-th post of IN's rows and columns (N divides side − 1; default 1), each height h
// written as round(S · h + O) (default S = 1, O = 0); voids (−32768) stay voids. OUT's file
// name places the tile (N22W160.hgt): keep IN's tile name. Exits 2 on bad usage, 1 when a
// height leaves the int16 range.
import { readFileSync, writeFileSync, mkdirSync } from 'node:fs';
import { dirname } from 'node:path';

const usage = () => {
  console.error('usage: node make_hgt.mjs IN.hgt OUT.hgt [--step N] [--scale S] [--offset O]');
  process.exit(2);
};
const args = process.argv.slice(2);
const opt = { step: 1, scale: 1, offset: 0 };
const files = [];
for (let i = 0; i < args.length; i++) {
  const m = /^--(step|scale|offset)$/.exec(args[i]);
  if (m) {
    const v = Number(args[++i]);
    if (!Number.isFinite(v)) usage();
    opt[m[1]] = v;
  } else if (args[i].startsWith('--')) {
    usage();
  } else {
    files.push(args[i]);
  }
}
if (files.length !== 2) usage();
const [inPath, outPath] = files;
const bytes = readFileSync(inPath);
const side = Math.round(Math.sqrt(bytes.length / 2));
if (side * side * 2 !== bytes.length || side < 2) {
  console.error(`make_hgt: ${inPath}: ${bytes.length} bytes is not a square grid of int16`);
  process.exit(1);
}
const step = opt.step;
if (!Number.isInteger(step) || step < 1 || (side - 1) % step !== 0) {
  console.error(`make_hgt: --step ${step} does not divide ${side - 1}`);
  process.exit(2);
}
const n = (side - 1) / step + 1;
const out = Buffer.alloc(2 * n * n);
for (let r = 0; r < n; r++) {
  for (let c = 0; c < n; c++) {
    const v = bytes.readInt16BE(2 * (r * step * side + c * step));
    let w = v;
    if (v !== -32768) {
      w = Math.round(opt.scale * v + opt.offset);
      if (w < -32767 || w > 32767) {
        console.error(`make_hgt: height ${v} becomes ${w}, outside int16`);
        process.exit(1);
      }
    }
    out.writeInt16BE(w, 2 * (r * n + c));
  }
}
mkdirSync(dirname(outPath), { recursive: true });
writeFileSync(outPath, out);
console.log(`make_hgt: ${outPath}: ${n} × ${n} posts`);
