// Checks a directory of Cesium quantized-mesh-1.0 terrain tiles (as `vtz tiles` writes them)
// with an independent decoder, HERE's @here/quantized-mesh-decoder from npm:
//
//   node check_terrain.mjs [--require-json] [--source FILE.hgt [--max-error E]] DIR
//
// DIR holds layer.json and {z}/{x}/{y}.terrain (gzipped or not). For every tile that
// layer.json's `available` ranges list it checks that the file exists and decodes, and:
// - every u, v, h code is in 0..32767; every index < vertex count; no triangle repeats an
//   index; every triangle is counter-clockwise seen from above (Cesium culls back faces) and
//   the triangles' areas add up to exactly the tile's square; every vertex is used;
// - the west/south/east/north edge lists are exactly the vertices with u == 0 / v == 0 /
//   u == 32767 / v == 32767;
// - the header: min <= max height; the bounding sphere holds every vertex; the horizon
//   occlusion point (in the ellipsoid-scaled frame) hides no vertex, and is not much farther
//   out than it needs to be (a point in metres instead of scaled units fails);
// - the extensions layer.json lists: octvertexnormals: 2 bytes per vertex, each normal
//   pointing away from the ellipsoid; watermask: 1 or 256 × 256 bytes;
// - beside the tile, {z}/{x}/{y}.json (vtz tiles --dump-json), when present, holds the values
//   the writer meant to encode: vertices [[u, v, h]...] and triangles [[a, b, c]...] must be
//   equal to the decoded ones in the same order, min/max height equal as float32, and
//   west/south/east/north the tile's rectangle in the TMS geographic scheme;
//   --require-json makes a missing one a failure;
// - neighbours at the same zoom (x ± 1 with the wrap at the antimeridian, y ± 1): the shared
//   edge has the same vertices, at the same positions along it and the same heights in metres
//   (min + h / 32767 × (max − min), within 1e-6 of the larger |height| or 1 m).
// - with --source FILE.hgt (an SRTM .hgt tile, placed by its file name: N22W160.hgt is
//   the square degree from 160° W, 22° N; posts at its corners and every 1/(side − 1)°;
//   -32768 void), every valid post inside each tile (its edges included) is located in the
//   decoded triangles (a post in none fails) and its height compared with the mesh's there
//   (barycentric in u, v of Cesium's decoded heights, lerp(min, max, h / 32767)); per zoom,
//   every post must be within the zoom's bound: --max-error E at the finest zoom and
//   max(E, Cesium's geometric error of the zoom) above it, or, without --max-error, the
//   `target` layer.json's `vtz.levels` states. layer.json's own `max_error` per zoom must
//   not be below the error measured here.
// It also fails on a .terrain file that layer.json does not list.
// Prints one summary line; exits 1 on any failure (each printed with its tile), 2 on bad usage.
import { readFileSync, readdirSync, existsSync, statSync } from 'node:fs';
import { join } from 'node:path';
import { gunzipSync } from 'node:zlib';
import decoderPkg from '@here/quantized-mesh-decoder';

// The package is CommonJS (UMD) with `exports.default = decode`.
const decode = decoderPkg.default ?? decoderPkg;

const Q = 32767;
const REL_TOL = 1e-6;
// WGS84 as Cesium has it (Ellipsoid.WGS84).
const RADII = [6378137.0, 6378137.0, 6356752.3142451793];

const USAGE = 'usage: node check_terrain.mjs [--require-json] [--source FILE.hgt [--max-error E]] DIR';
const args = process.argv.slice(2);
let requireJson = false;
let sourcePath = null;
let maxError = null;
const rest = [];
for (let i = 0; i < args.length; i++) {
  if (args[i] === '--require-json') requireJson = true;
  else if (args[i] === '--source' && i + 1 < args.length) sourcePath = args[++i];
  else if (args[i] === '--max-error' && i + 1 < args.length) maxError = Number(args[++i]);
  else rest.push(args[i]);
}
if (rest.length !== 1 || rest[0].startsWith('-') || (maxError !== null && !(maxError >= 0)) ||
    (maxError !== null && sourcePath === null)) {
  console.error(USAGE);
  process.exit(2);
}
const dir = rest[0];
if (!existsSync(join(dir, 'layer.json'))) {
  console.error(`check_terrain: ${dir}: no layer.json`);
  process.exit(2);
}

const failures = [];
const notes = [];
const fail = (where, msg) => failures.push(`${where}: ${msg}`);

// ---- layer.json
let layer;
try {
  layer = JSON.parse(readFileSync(join(dir, 'layer.json'), 'utf8'));
} catch (e) {
  console.error(`check_terrain: layer.json: ${e.message}`);
  process.exit(1);
}
const expect = (cond, msg) => cond || fail('layer.json', msg);
expect(typeof layer.tilejson === 'string' && layer.tilejson.startsWith('2.'), `tilejson ${JSON.stringify(layer.tilejson)}, expected 2.x`);
expect(layer.format === 'quantized-mesh-1.0', `format ${JSON.stringify(layer.format)}`);
expect(layer.scheme === 'tms', `scheme ${JSON.stringify(layer.scheme)}, expected tms`);
expect(layer.projection === undefined || layer.projection === 'EPSG:4326', `projection ${JSON.stringify(layer.projection)}: only EPSG:4326 is checked`);
const template = Array.isArray(layer.tiles) ? layer.tiles[0] : undefined;
expect(typeof template === 'string' && /^\{z\}\/\{x\}\/\{y\}\.terrain(\?|$)/.test(template),
  `tiles ${JSON.stringify(layer.tiles)}, expected ["{z}/{x}/{y}.terrain..."]`);
expect(Array.isArray(layer.available), 'no `available` array');
const extensions = Array.isArray(layer.extensions) ? layer.extensions : [];
const wantNormals = extensions.includes('octvertexnormals');
const wantWater = extensions.includes('watermask');
if (failures.length) {
  for (const f of failures) console.error(`FAIL ${f}`);
  process.exit(1);
}

// ---- the source raster (--source)
let source = null;
if (sourcePath !== null) {
  const m = /([NS])(\d{2})([EW])(\d{3})[^\/]*\.hgt$/i.exec(sourcePath);
  let raw;
  try {
    raw = readFileSync(sourcePath);
  } catch (e) {
    console.error(`check_terrain: --source ${sourcePath}: ${e.message}`);
    process.exit(2);
  }
  const side = Math.round(Math.sqrt(raw.length / 2));
  if (!m || side < 2 || side * side * 2 !== raw.length) {
    console.error(`check_terrain: --source ${sourcePath}: not an .hgt tile named like N22W160.hgt of side² int16`);
    process.exit(2);
  }
  const posts = new Int16Array(side * side);
  for (let i = 0; i < side * side; i++) posts[i] = raw.readInt16BE(2 * i);
  source = {
    side,
    posts,
    west: (m[3].toUpperCase() === 'W' ? -1 : 1) * Number(m[4]),
    south: (m[1].toUpperCase() === 'S' ? -1 : 1) * Number(m[2]),
    d: 1 / (side - 1),
  };
}
// Per zoom: posts measured, the largest |mesh − post|, and where.
const bound = new Map();

// Every valid post of the source inside tile z/x/y, located in its decoded triangles.
function measureTile(key, z, rect, u, v, hMetres, triangleIndices) {
  const { side, posts, west, south, d } = source;
  const north = south + 1;
  const eps = 1e-9;
  const c0 = Math.max(0, Math.ceil((rect.west - west) / d - eps));
  const c1 = Math.min(side - 1, Math.floor((rect.east - west) / d + eps));
  const r0 = Math.max(0, Math.ceil((north - rect.north) / d - eps));
  const r1 = Math.min(side - 1, Math.floor((north - rect.south) / d + eps));
  if (c0 > c1 || r0 > r1) return;
  const cw = c1 - c0 + 1;
  const err = new Float64Array(cw * (r1 - r0 + 1)).fill(NaN);
  // Post positions in tile units (u east, v north).
  const pu = (c) => ((west + c * d - rect.west) / (rect.east - rect.west)) * Q;
  const pv = (r) => ((north - r * d - rect.south) / (rect.north - rect.south)) * Q;
  const tol = 1e-6;
  for (let t = 0; t < triangleIndices.length; t += 3) {
    const a = triangleIndices[t];
    const b = triangleIndices[t + 1];
    const c = triangleIndices[t + 2];
    const [ax, ay, bx, by, cx, cy] = [u[a], v[a], u[b], v[b], u[c], v[c]];
    const det = (bx - ax) * (cy - ay) - (cx - ax) * (by - ay);
    if (det === 0) continue;
    const umin = Math.min(ax, bx, cx);
    const umax = Math.max(ax, bx, cx);
    const vmin = Math.min(ay, by, cy);
    const vmax = Math.max(ay, by, cy);
    // Candidate posts: columns and rows whose positions fall in the triangle's box.
    const toLon = (x) => rect.west + (x / Q) * (rect.east - rect.west);
    const toLat = (y) => rect.south + (y / Q) * (rect.north - rect.south);
    const cc0 = Math.max(c0, Math.ceil((toLon(umin) - west) / d - 1e-6));
    const cc1 = Math.min(c1, Math.floor((toLon(umax) - west) / d + 1e-6));
    const rr0 = Math.max(r0, Math.ceil((north - toLat(vmax)) / d - 1e-6));
    const rr1 = Math.min(r1, Math.floor((north - toLat(vmin)) / d + 1e-6));
    for (let r = rr0; r <= rr1; r++) {
      const y = pv(r);
      for (let col = cc0; col <= cc1; col++) {
        const h = posts[r * side + col];
        if (h === -32768) continue;
        const x = pu(col);
        const l1 = ((x - ax) * (cy - ay) - (cx - ax) * (y - ay)) / det;
        const l2 = ((bx - ax) * (y - ay) - (x - ax) * (by - ay)) / det;
        const l0 = 1 - l1 - l2;
        if (l0 < -tol || l1 < -tol || l2 < -tol) continue;
        const e = Math.abs(l0 * hMetres[a] + l1 * hMetres[b] + l2 * hMetres[c] - h);
        const i = (r - r0) * cw + col - c0;
        if (Number.isNaN(err[i]) || e > err[i]) err[i] = e;
      }
    }
  }
  const target = targetOf(z);
  let s = bound.get(z);
  if (!s) bound.set(z, (s = { posts: 0, max: 0, at: '', over: 0, target }));
  let missing = 0;
  for (let r = r0; r <= r1; r++) {
    for (let col = c0; col <= c1; col++) {
      if (posts[r * side + col] === -32768) continue;
      const e = err[(r - r0) * cw + col - c0];
      if (Number.isNaN(e)) {
        if (missing++ === 0) fail(key, `source post (${col}, ${r}) lies in no triangle`);
        continue;
      }
      s.posts++;
      if (e > s.max) {
        s.max = e;
        s.at = `${key} post (${col}, ${r})`;
      }
      if (e > target) s.over++;
    }
  }
  if (missing > 1) fail(key, `${missing} source posts lie in no triangle`);
}

// Listed tiles, key "z/x/y".
const listed = new Map();
layer.available.forEach((ranges, z) => {
  if (!Array.isArray(ranges)) return fail('layer.json', `available[${z}] is not an array`);
  for (const r of ranges) {
    const { startX, startY, endX, endY } = r;
    if (![startX, startY, endX, endY].every(Number.isInteger) || startX > endX || startY > endY) {
      fail('layer.json', `available[${z}]: bad range ${JSON.stringify(r)}`);
      continue;
    }
    if (startX < 0 || startY < 0 || endX >= 2 ** (z + 1) || endY >= 2 ** z) {
      fail('layer.json', `available[${z}]: range ${JSON.stringify(r)} outside the zoom's ${2 ** (z + 1)} × ${2 ** z} tiles`);
      continue;
    }
    for (let x = startX; x <= endX; x++) {
      for (let y = startY; y <= endY; y++) {
        const key = `${z}/${x}/${y}`;
        if (listed.has(key)) notes.push(`${key} is listed twice`);
        listed.set(key, { z, x, y });
      }
    }
  }
});

// .terrain files on disk that are not listed.
for (const zd of readdirSync(dir)) {
  if (!/^\d+$/.test(zd) || !statSync(join(dir, zd)).isDirectory()) continue;
  for (const xd of readdirSync(join(dir, zd))) {
    if (!statSync(join(dir, zd, xd)).isDirectory()) continue;
    for (const f of readdirSync(join(dir, zd, xd))) {
      const m = /^(\d+)\.terrain$/.exec(f);
      if (m && !listed.has(`${Number(zd)}/${Number(xd)}/${Number(m[1])}`)) {
        fail(`${zd}/${xd}/${m[1]}`, 'a .terrain file that layer.json does not list as available');
      }
    }
  }
}

// The bound of zoom z: --max-error at the finest zoom and Cesium's geometric error of the
// zoom above it (TerrainProvider.getEstimatedLevelZeroGeometricErrorForAHeightmap(WGS84, 65,
// 2) / 2^z), or what layer.json states.
const finestZoom = Math.max(-1, ...[...listed.values()].map((t) => t.z));
const vtzLevels = Array.isArray(layer.vtz?.levels) ? layer.vtz.levels : [];
function targetOf(z) {
  if (maxError !== null) {
    const ge = (RADII[0] * 2 * Math.PI * 0.25) / (65 * 2) / 2 ** z;
    return z === finestZoom ? maxError : Math.max(maxError, ge);
  }
  const l = vtzLevels.find((q) => q.zoom === z);
  if (!l || !Number.isFinite(l.target)) {
    fail('layer.json', `no vtz.levels target for zoom ${z}: give --max-error`);
    return Infinity;
  }
  return l.target;
}

// ---- geometry helpers
function tileRect(z, x, y) {
  const w = 180 / 2 ** z;
  return { west: -180 + x * w, south: -90 + y * w, east: -180 + (x + 1) * w, north: -90 + (y + 1) * w };
}
const rad = (d) => (d * Math.PI) / 180;
function surfaceNormal(lonDeg, latDeg) {
  const lon = rad(lonDeg);
  const lat = rad(latDeg);
  return [Math.cos(lat) * Math.cos(lon), Math.cos(lat) * Math.sin(lon), Math.sin(lat)];
}
// Cesium's Ellipsoid.cartographicToCartesian.
function ecef(lonDeg, latDeg, h) {
  const n = surfaceNormal(lonDeg, latDeg);
  const k = n.map((c, i) => RADII[i] * RADII[i] * c);
  const gamma = Math.sqrt(n[0] * k[0] + n[1] * k[1] + n[2] * k[2]);
  return k.map((c, i) => c / gamma + n[i] * h);
}
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const norm = (a) => Math.sqrt(dot(a, a));
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
// Cesium's EllipsoidalOccluder computeMagnitude: the scaled-space magnitude along direction
// `d` (unit) beyond which `p` is above the horizon of a point there; negative or infinite when
// no such magnitude exists.
function requiredMagnitude(p, d) {
  const s = p.map((c, i) => c / RADII[i]);
  let m2 = dot(s, s);
  let m = Math.sqrt(m2);
  const dir = s.map((c) => c / m);
  m2 = Math.max(1, m2);
  m = Math.max(1, m);
  const cosA = dot(dir, d);
  const sinA = norm(cross(dir, d));
  const cosB = 1 / m;
  const sinB = Math.sqrt(m2 - 1) * cosB;
  return 1 / (cosA * cosB - sinA * sinB);
}
// Cesium's AttributeCompression.octDecodeInRange(x, y, 255).
function octDecode(bx, by) {
  let x = (Math.min(Math.max(bx, 0), 255) / 255) * 2 - 1;
  let y = (Math.min(Math.max(by, 0), 255) / 255) * 2 - 1;
  const z = 1 - (Math.abs(x) + Math.abs(y));
  if (z < 0) {
    const ox = x;
    x = (1 - Math.abs(y)) * (ox >= 0 ? 1 : -1);
    y = (1 - Math.abs(ox)) * (y >= 0 ? 1 : -1);
  }
  const v = [x, y, z];
  const l = norm(v);
  return v.map((c) => c / l);
}

// ---- the tiles
const tiles = new Map(); // key -> { z, x, y, u, v, hm (heights in metres), edges }
let nVertices = 0;
let nTriangles = 0;
let nJson = 0;
let nGzip = 0;
let worstNormalDot = Infinity;
let horizonChecked = 0;
let horizonNA = 0;

const sorted = [...listed.values()].sort((a, b) => a.z - b.z || a.x - b.x || a.y - b.y);
for (const { z, x, y } of sorted) {
  const key = `${z}/${x}/${y}`;
  const path = join(dir, String(z), String(x), `${y}.terrain`);
  let bytes;
  try {
    bytes = readFileSync(path);
  } catch {
    fail(key, `listed as available but ${path} is missing`);
    continue;
  }
  if (bytes.length >= 2 && bytes[0] === 0x1f && bytes[1] === 0x8b) {
    try {
      bytes = gunzipSync(bytes);
      nGzip++;
    } catch (e) {
      fail(key, `gzip: ${e.message}`);
      continue;
    }
  }
  // The decoder reads typed arrays at offsets of the ArrayBuffer it is given: it must be the
  // tile's own bytes, not Node's shared buffer pool.
  const ab = bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength);
  let t;
  const warnings = [];
  const warn = console.warn;
  console.warn = (...a) => warnings.push(a.join(' '));
  try {
    t = decode(ab);
  } catch (e) {
    fail(key, `does not decode (${bytes.length} bytes): ${e.message}`);
    continue;
  } finally {
    console.warn = warn;
  }
  for (const w of warnings) fail(key, `decoder: ${w}`);

  const { header, vertexData, triangleIndices } = t;
  const n = vertexData.length / 3;
  const nt = triangleIndices.length / 3;
  nVertices += n;
  nTriangles += nt;
  const u = vertexData.subarray(0, n);
  const v = vertexData.subarray(n, 2 * n);
  const h = vertexData.subarray(2 * n, 3 * n);
  const minH = header.minHeight;
  const maxH = header.maxHeight;
  const rect = tileRect(z, x, y);

  if (n < 3 || nt < 1) fail(key, `${n} vertices, ${nt} triangles`);
  for (let i = 0; i < n; i++) {
    if (u[i] > Q || v[i] > Q || h[i] > Q) {
      fail(key, `vertex ${i} = (${u[i]}, ${v[i]}, ${h[i]}): a code above ${Q}`);
      break;
    }
  }
  if (!(Number.isFinite(minH) && Number.isFinite(maxH) && minH <= maxH)) {
    fail(key, `header heights min ${minH}, max ${maxH}`);
  }

  // Triangles.
  const used = new Uint8Array(n);
  let badIndex = 0;
  let degenerate = 0;
  let clockwise = 0;
  let flat = 0;
  let area2 = 0;
  for (let t3 = 0; t3 < nt; t3++) {
    const a = triangleIndices[3 * t3];
    const b = triangleIndices[3 * t3 + 1];
    const c = triangleIndices[3 * t3 + 2];
    if (a >= n || b >= n || c >= n) {
      if (badIndex++ === 0) fail(key, `triangle ${t3} = [${a}, ${b}, ${c}]: index >= vertex count ${n}`);
      continue;
    }
    used[a] = used[b] = used[c] = 1;
    if (a === b || b === c || a === c) {
      if (degenerate++ === 0) fail(key, `triangle ${t3} = [${a}, ${b}, ${c}] repeats an index`);
      continue;
    }
    const cr = (u[b] - u[a]) * (v[c] - v[a]) - (v[b] - v[a]) * (u[c] - u[a]);
    area2 += cr;
    if (cr < 0 && clockwise++ === 0) fail(key, `triangle ${t3} = [${a}, ${b}, ${c}] is clockwise seen from above`);
    if (cr === 0 && flat++ === 0) fail(key, `triangle ${t3} = [${a}, ${b}, ${c}] has zero area in (u, v)`);
  }
  if (badIndex > 1) fail(key, `${badIndex} triangles with an index out of range`);
  if (degenerate > 1) fail(key, `${degenerate} triangles repeat an index`);
  if (clockwise > 1) fail(key, `${clockwise} clockwise triangles`);
  if (flat > 1) fail(key, `${flat} zero-area triangles`);
  if (!badIndex && !clockwise && area2 !== 2 * Q * Q) {
    fail(key, `the triangles cover ${(area2 / (2 * Q * Q)).toFixed(6)} of the tile's square (holes or overlaps)`);
  }
  const unused = n - used.reduce((s, k) => s + k, 0);
  if (!badIndex && unused) fail(key, `${unused} vertices in no triangle`);

  // Edge lists.
  const edgeDefs = [
    ['west', t.westIndices, (i) => u[i] === 0],
    ['south', t.southIndices, (i) => v[i] === 0],
    ['east', t.eastIndices, (i) => u[i] === Q],
    ['north', t.northIndices, (i) => v[i] === Q],
  ];
  for (const [name, list, on] of edgeDefs) {
    const want = [];
    for (let i = 0; i < n; i++) if (on(i)) want.push(i);
    const got = [...list].sort((p, q) => p - q);
    const dup = got.some((k, i) => i > 0 && got[i - 1] === k);
    if (dup || got.length !== want.length || got.some((k, i) => k !== want[i])) {
      const gs = new Set(got);
      const ws = new Set(want);
      fail(key, `${name} edge list [${list.length}] is not the ${want.length} vertices on that edge` +
        `${dup ? ' (it repeats an index)' : ''}; listed but not on it: ${JSON.stringify(got.filter((k) => !ws.has(k)).slice(0, 8))}` +
        `, on it but not listed: ${JSON.stringify(want.filter((k) => !gs.has(k)).slice(0, 8))}`);
    }
  }

  // The source's posts against the mesh, with heights as Cesium decodes them
  // (CesiumMath.lerp(minimumHeight, maximumHeight, h / 32767)).
  if (source) {
    const hc = new Float64Array(n);
    for (let k = 0; k < n; k++) {
      const f = h[k] / Q;
      hc[k] = (1 - f) * minH + f * maxH;
    }
    measureTile(key, z, rect, u, v, hc, triangleIndices);
  }

  // Positions: longitude, latitude, height in metres.
  const heightM = (k) => minH + (h[k] / Q) * (maxH - minH);
  const lonOf = (k) => rect.west + (u[k] / Q) * (rect.east - rect.west);
  const latOf = (k) => rect.south + (v[k] / Q) * (rect.north - rect.south);
  const pts = [];
  for (let k = 0; k < n; k++) pts.push(ecef(lonOf(k), latOf(k), heightM(k)));

  // Bounding sphere.
  const c = [header.boundingSphereCenterX, header.boundingSphereCenterY, header.boundingSphereCenterZ];
  const r = header.boundingSphereRadius;
  if (![...c, r].every(Number.isFinite) || r < 0) {
    fail(key, `bounding sphere ${JSON.stringify([...c, r])}`);
  } else {
    let worst = 0;
    for (const p of pts) worst = Math.max(worst, norm([p[0] - c[0], p[1] - c[1], p[2] - c[2]]));
    if (worst > r * (1 + 1e-4) + 1) {
      fail(key, `a vertex ${worst.toFixed(3)} m from the bounding sphere's centre, radius ${r.toFixed(3)} m`);
    }
  }

  // Horizon occlusion point (ellipsoid-scaled frame).
  const hp = [header.horizonOcclusionPointX, header.horizonOcclusionPointY, header.horizonOcclusionPointZ];
  const hpm = norm(hp);
  if (!hp.every(Number.isFinite) || !(hpm > 0)) {
    fail(key, `horizon occlusion point ${JSON.stringify(hp)}`);
  } else {
    // The magnitude along unit direction d beyond which a point hides no vertex (NaN when no
    // such point exists: some vertex faces away from d, as in a hemisphere-wide tile).
    const needAlong = (d) => {
      let need = 0;
      for (const p of pts) {
        const m = requiredMagnitude(p, d);
        if (!(m > 0) || !Number.isFinite(m)) return NaN;
        need = Math.max(need, m);
      }
      return need;
    };
    const need = needAlong(hp.map((k) => k / hpm));
    if (Number.isNaN(need)) {
      horizonNA++;
    } else {
      horizonChecked++;
      if (hpm < need * (1 - REL_TOL)) {
        fail(key, `horizon occlusion point at scaled magnitude ${hpm} hides vertices: it needs ${need}`);
      } else if (hpm > need * (1 + 1e-3)) {
        // A point written in metres (ECEF) instead of the ellipsoid-scaled frame?
        const sp = hp.map((k, i) => k / RADII[i]);
        const spm = norm(sp);
        const spNeed = needAlong(sp.map((k) => k / spm));
        const metres = spm >= spNeed * (1 - REL_TOL) && spm <= spNeed * (1 + 1e-3);
        fail(key, `horizon occlusion point at scaled magnitude ${hpm.toPrecision(8)}, ${(hpm / need).toPrecision(4)} × the ${need.toPrecision(8)} ` +
          `it needs${metres ? ': it is in metres (ECEF); divided by the WGS84 radii it would be right' : ''}`);
      }
    }
  }

  // Extensions.
  const ext = t.extensions ?? {};
  if (wantNormals) {
    const nb = ext.vertexNormals;
    if (!nb) {
      fail(key, 'no octvertexnormals extension, though layer.json lists it');
    } else if (nb.length !== 2 * n) {
      fail(key, `octvertexnormals: ${nb.length} bytes for ${n} vertices (want ${2 * n})`);
    } else {
      let bad = 0;
      for (let k = 0; k < n; k++) {
        const nrm = octDecode(nb[2 * k], nb[2 * k + 1]);
        const up = surfaceNormal(lonOf(k), latOf(k));
        const dd = dot(nrm, up);
        worstNormalDot = Math.min(worstNormalDot, dd);
        if (!(dd > 0) && bad++ === 0) {
          fail(key, `vertex ${k}'s normal ${JSON.stringify(nrm.map((q) => +q.toFixed(4)))} points into the ellipsoid (dot with up ${dd.toFixed(4)})`);
        }
      }
      if (bad > 1) fail(key, `${bad} normals point into the ellipsoid`);
    }
  }
  if (wantWater) {
    const wm = ext.waterMask;
    if (!wm) fail(key, 'no watermask extension, though layer.json lists it');
    else if (wm.byteLength !== 1 && wm.byteLength !== 65536) fail(key, `watermask of ${wm.byteLength} bytes (want 1 or 65536)`);
  }

  // The writer's own values.
  const jsonPath = join(dir, String(z), String(x), `${y}.json`);
  if (existsSync(jsonPath)) {
    nJson++;
    let j;
    try {
      j = JSON.parse(readFileSync(jsonPath, 'utf8'));
    } catch (e) {
      fail(key, `${jsonPath}: ${e.message}`);
    }
    if (j) {
      if (!Array.isArray(j.vertices) || j.vertices.length !== n) {
        fail(key, `${n} vertices decoded, the json has ${j.vertices?.length}`);
      } else {
        const k = j.vertices.findIndex((p, i) => p[0] !== u[i] || p[1] !== v[i] || p[2] !== h[i]);
        if (k >= 0) fail(key, `vertex ${k}: decoded (${u[k]}, ${v[k]}, ${h[k]}), the json has ${JSON.stringify(j.vertices[k])}`);
      }
      if (!Array.isArray(j.triangles) || j.triangles.length !== nt) {
        fail(key, `${nt} triangles decoded, the json has ${j.triangles?.length}`);
      } else {
        const k = j.triangles.findIndex((p, i) =>
          p[0] !== triangleIndices[3 * i] || p[1] !== triangleIndices[3 * i + 1] || p[2] !== triangleIndices[3 * i + 2]);
        if (k >= 0) fail(key, `triangle ${k}: decoded ${JSON.stringify([...triangleIndices.subarray(3 * k, 3 * k + 3)])}, the json has ${JSON.stringify(j.triangles[k])}`);
      }
      if (Math.fround(j.min_height) !== minH || Math.fround(j.max_height) !== maxH) {
        fail(key, `header heights ${minH}..${maxH}, the json has ${j.min_height}..${j.max_height}`);
      }
      for (const side of ['west', 'south', 'east', 'north']) {
        if (!(Math.abs(j[side] - rect[side]) <= 1e-9)) {
          fail(key, `json ${side} ${j[side]}, the TMS geographic tile's is ${rect[side]}`);
        }
      }
    }
  } else if (requireJson) {
    fail(key, `no ${jsonPath} (--require-json)`);
  }

  // Edge vertices for the neighbour checks: position along the edge and height in metres.
  const edge = (list, along) => [...list].map((k) => [along[k], heightM(k)]).sort((p, q) => p[0] - q[0]);
  tiles.set(key, {
    minH, maxH,
    west: edge(t.westIndices, v), east: edge(t.eastIndices, v),
    south: edge(t.southIndices, u), north: edge(t.northIndices, u),
  });
}

// ---- neighbours
let pairs = 0;
let worstDiff = 0;
let worstDiffAt = '';
function compareEdge(keyA, sideA, keyB, sideB) {
  const A = tiles.get(keyA);
  const B = tiles.get(keyB);
  if (!A || !B) return;
  pairs++;
  const ea = A[sideA];
  const eb = B[sideB];
  const where = `${keyA} ${sideA} edge / ${keyB} ${sideB} edge`;
  const pa = ea.map((p) => p[0]);
  const pb = eb.map((p) => p[0]);
  if (pa.length !== pb.length || pa.some((p, i) => p !== pb[i])) {
    const sa = new Set(pa);
    const sb = new Set(pb);
    fail(where, `different vertices along the edge (${pa.length} / ${pb.length}); only in ${keyA}: ` +
      `${JSON.stringify(pa.filter((p) => !sb.has(p)).slice(0, 8))}, only in ${keyB}: ${JSON.stringify(pb.filter((p) => !sa.has(p)).slice(0, 8))}`);
    return;
  }
  let bad = 0;
  for (let i = 0; i < ea.length; i++) {
    const diff = Math.abs(ea[i][1] - eb[i][1]);
    if (diff > worstDiff) {
      worstDiff = diff;
      worstDiffAt = `${where} at ${ea[i][0]}`;
    }
    const tol = REL_TOL * Math.max(1, Math.abs(ea[i][1]), Math.abs(eb[i][1]));
    if (diff > tol && bad++ === 0) {
      fail(where, `at ${ea[i][0]} heights ${ea[i][1]} m / ${eb[i][1]} m differ by ${diff} m`);
    }
  }
  if (bad > 1) fail(where, `${bad} vertices with different heights`);
}
for (const { z, x, y } of sorted) {
  const key = `${z}/${x}/${y}`;
  const nx = 2 ** (z + 1);
  compareEdge(key, 'east', `${z}/${(x + 1) % nx}/${y}`, 'west');
  if (y + 1 < 2 ** z) compareEdge(key, 'north', `${z}/${x}/${y + 1}`, 'south');
}

// Tiles whose parent is not listed (Cesium reaches a tile only through its ancestors).
const orphans = sorted.filter(({ z, x, y }) => z > 0 && !listed.has(`${z - 1}/${x >> 1}/${y >> 1}`));
if (orphans.length) notes.push(`${orphans.length} tiles whose parent is not listed, e.g. ${orphans[0].z}/${orphans[0].x}/${orphans[0].y}`);

// ---- the bound per zoom (--source)
const boundLines = [];
if (source) {
  if (bound.size === 0) fail(sourcePath, 'no source post lies in any listed tile');
  for (const [z, s] of [...bound.entries()].sort((a, b) => a[0] - b[0])) {
    const claimed = vtzLevels.find((q) => q.zoom === z)?.max_error;
    boundLines.push(`zoom ${z}: ${s.posts} posts, max error ${s.max.toFixed(4)} (${s.at || '-'}), ` +
      `${s.over} over the bound ${s.target}` + (Number.isFinite(claimed) ? `; layer.json says max error ${claimed.toFixed(4)}` : ''));
    if (s.over > 0) {
      fail(`zoom ${z}`, `${s.over} of ${s.posts} source posts farther than the bound ${s.target} from the decoded mesh (max error ${s.max} at ${s.at})`);
    }
    if (Number.isFinite(claimed) && claimed < s.max - 1e-6 * Math.max(1, s.max)) {
      fail(`zoom ${z}`, `layer.json says max error ${claimed}, measured here ${s.max}`);
    }
  }
}

finish();

function finish() {
  for (const line of boundLines) console.log(`bound: ${line}`);
  for (const note of notes) console.log(`note: ${note}`);
  const zooms = sorted.length ? `zooms ${sorted[0].z}–${sorted[sorted.length - 1].z}` : 'no zooms';
  const summary = `check_terrain ${dir}: ${sorted.length} tiles (${zooms}, ${nGzip} gzipped, ${nJson} with json), ` +
    `${nVertices} vertices, ${nTriangles} triangles, ${pairs} neighbour edges, worst neighbour height difference ` +
    `${worstDiff.toExponential(3)} m${worstDiffAt ? ` (${worstDiffAt})` : ''}; horizon point checked on ${horizonChecked} tiles ` +
    `(${horizonNA} hemisphere-wide)` + (Number.isFinite(worstNormalDot) ? `; lowest normal·up ${worstNormalDot.toFixed(3)}` : '') +
    (source ? `; every post of ${sourcePath} checked against its zoom's bound (${bound.size} zooms)` : '');
  if (failures.length) {
    const max = 60;
    for (const f of failures.slice(0, max)) console.error(`FAIL ${f}`);
    if (failures.length > max) console.error(`FAIL ... and ${failures.length - max} more`);
    console.error(`${summary}: ${failures.length} failures`);
    process.exit(1);
  }
  console.log(`${summary}: ok`);
  process.exit(0);
}
