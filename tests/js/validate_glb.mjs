// Validates .glb files with the Khronos glTF validator (the npm build of
// KhronosGroup/glTF-Validator): node validate_glb.mjs [--allow-warnings] FILE.glb...
//
// Prints each file's counts and every issue (severity, code, JSON pointer, message). Exits 1
// when any file has an error, or a warning unless --allow-warnings is given; infos and hints
// are printed but pass. Exits 2 on bad usage or an unreadable file.
import { readFile } from 'node:fs/promises';
import validator from 'gltf-validator';

const SEVERITY = ['error', 'warning', 'info', 'hint'];

const args = process.argv.slice(2);
const allowWarnings = args.includes('--allow-warnings');
const files = args.filter((a) => a !== '--allow-warnings');
if (files.length === 0 || files.some((f) => f.startsWith('--'))) {
  console.error('usage: node validate_glb.mjs [--allow-warnings] FILE.glb...');
  process.exit(2);
}

let failed = 0;
for (const file of files) {
  let bytes;
  try {
    bytes = new Uint8Array(await readFile(file));
  } catch (e) {
    console.error(`${file}: ${e.message}`);
    process.exit(2);
  }
  const report = await validator.validateBytes(bytes, {
    uri: file,
    maxIssues: 0, // no limit
    // A .glb from vtz is self-contained: any external reference is an error in itself.
    externalResourceFunction: (uri) => Promise.reject(new Error(`external resource ${uri}`)),
  });
  const { numErrors, numWarnings, numInfos, numHints, messages } = report.issues;
  const bad = numErrors > 0 || (!allowWarnings && numWarnings > 0);
  if (bad) failed += 1;
  const generator = report.info?.generator ?? '?';
  console.log(
    `${bad ? 'FAIL' : 'ok  '} ${file}: ${numErrors} errors, ${numWarnings} warnings, ` +
      `${numInfos} infos, ${numHints} hints (generator ${generator}, validator ${report.validatorVersion})`
  );
  for (const m of messages) {
    console.log(`    ${SEVERITY[m.severity] ?? m.severity} ${m.code} ${m.pointer ?? ''} ${m.message}`);
  }
}
console.log(`${files.length - failed} passed, ${failed} failed`);
process.exit(failed > 0 ? 1 : 0);
