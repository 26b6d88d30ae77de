// A small PMTiles v3 reader (header, gzip or plain directories of varints, leaf directories),
// for a whole archive in memory: the browser page and Node use the same code.

async function gunzip(/** @type {Uint8Array} */ b) {
  const s = new Blob([b]).stream().pipeThrough(new DecompressionStream('gzip'));
  return new Uint8Array(await new Response(s).arrayBuffer());
}

function readDir(/** @type {Uint8Array} */ b) {
  let pos = 0;
  const v = () => {
    let r = 0, mul = 1, c;
    do { c = b[pos++]; r += (c & 0x7f) * mul; mul *= 128; } while (c >= 0x80);
    return r;
  };
  const n = v();
  const ids = [], runs = [], lens = [], offs = [];
  let id = 0;
  for (let i = 0; i < n; i++) ids.push((id += v()));
  for (let i = 0; i < n; i++) runs.push(v());
  for (let i = 0; i < n; i++) lens.push(v());
  for (let i = 0; i < n; i++) {
    const o = v();
    offs.push(o === 0 && i > 0 ? offs[i - 1] + lens[i - 1] : o - 1);
  }
  return ids.map((id, i) => ({ id, run: runs[i], off: offs[i], len: lens[i] }));
}

export function zoomOf(/** @type {number} */ id) {
  let z = 0, base = 0;
  while (base + 4 ** z <= id) { base += 4 ** z; z++; }
  return z;
}

/** @returns {Promise<{tileType: number, minZoom: number, maxZoom: number, tiles: {id: number, z: number, bytes: Uint8Array}[]}>} */
export async function readArchive(/** @type {ArrayBuffer} */ buf) {
  const u8 = new Uint8Array(buf);
  const dv = new DataView(buf);
  if (new TextDecoder().decode(u8.subarray(0, 7)) !== 'PMTiles' || u8[7] !== 3) throw new Error('not PMTiles v3');
  const q = (/** @type {number} */ o) => Number(dv.getBigUint64(o, true));
  const [rootOff, rootLen, leafOff, dataOff] = [q(8), q(16), q(40), q(56)];
  const internal = u8[97];
  const tiles = [];
  const walk = async (/** @type {number} */ off, /** @type {number} */ len) => {
    let d = u8.subarray(off, off + len);
    if (internal === 2) d = await gunzip(d);
    for (const e of readDir(d)) {
      if (e.run === 0) await walk(leafOff + e.off, e.len);
      else for (let k = 0; k < e.run; k++) {
        tiles.push({ id: e.id + k, z: zoomOf(e.id + k), bytes: u8.subarray(dataOff + e.off, dataOff + e.off + e.len) });
      }
    }
  };
  await walk(rootOff, rootLen);
  return { tileType: u8[99], minZoom: u8[100], maxZoom: u8[101], tiles };
}
