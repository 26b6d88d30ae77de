"""A small PMTiles v3 reader and writer (from the spec: 127-byte header, directories of
varints, gzip or uncompressed), enough for benches/web: every addressed tile by tile id, and
archives of re-encoded tiles with the same ids."""
import gzip, hashlib, struct

HEADER = struct.Struct('<7sB' + 'Q' * 11 + 'BBBBBB' + 'iiii' + 'B' + 'ii')


def zoom_of(tile_id):
    z, base = 0, 0
    while base + 4 ** z <= tile_id:
        base += 4 ** z
        z += 1
    return z


def _varints(buf):
    pos = 0
    while pos < len(buf):
        v, shift = 0, 0
        while True:
            b = buf[pos]; pos += 1
            v |= (b & 0x7F) << shift; shift += 7
            if b < 0x80:
                break
        yield v


def _decomp(buf, c):
    return gzip.decompress(buf) if c == 2 else buf


def _dir(buf):
    it = _varints(buf)
    n = next(it)
    ids, tid = [], 0
    for _ in range(n):
        tid += next(it); ids.append(tid)
    runs = [next(it) for _ in range(n)]
    lens = [next(it) for _ in range(n)]
    offs = []
    for i in range(n):
        v = next(it)
        offs.append(offs[i - 1] + lens[i - 1] if v == 0 and i > 0 else v - 1)
    return list(zip(ids, runs, offs, lens))


def read(path):
    """-> (header dict, {tile_id: bytes}) for every addressed tile, file size."""
    data = open(path, 'rb').read()
    f = HEADER.unpack_from(data, 0)
    assert f[0] == b'PMTiles' and f[1] == 3, path
    h = dict(root_off=f[2], root_len=f[3], leaf_off=f[6], data_off=f[8], addressed=f[10],
             entries=f[11], contents=f[12], internal=f[14], tile_comp=f[15], tile_type=f[16],
             min_zoom=f[17], max_zoom=f[18], bounds=f[19:23], center=f[23:26])
    h['meta'] = data[f[4]:f[4] + f[5]]
    tiles = {}

    def walk(off, length):
        for tid, run, o, n in _dir(_decomp(data[off:off + length], h['internal'])):
            if run == 0:
                walk(h['leaf_off'] + o, n)
            else:
                for k in range(run):
                    tiles[tid + k] = data[h['data_off'] + o:h['data_off'] + o + n]
    walk(h['root_off'], h['root_len'])
    return h, tiles, len(data)


def _enc_varint(v, out):
    while v >= 0x80:
        out.append((v & 0x7F) | 0x80); v >>= 7
    out.append(v)


def write(path, tiles, like, tile_type=0):
    """Write {tile_id: bytes} with `like`'s header fields (bounds, zooms, center) and
    metadata: identical contents stored once, runs of equal consecutive tiles as one entry,
    the tile data at `like`'s data offset where that is larger (the pmtiles crate pads the
    header and root directory to 16 KiB), so sizes compare with vtz web's; -> file size."""
    ids = sorted(tiles)
    blobs, where, entries = bytearray(), {}, []
    for tid in ids:
        b = tiles[tid]
        key = hashlib.sha256(b).digest()
        if key not in where:
            where[key] = (len(blobs), len(b)); blobs += b
        off, n = where[key]
        if entries and entries[-1][0] + entries[-1][1] == tid and entries[-1][2] == off:
            entries[-1][1] += 1
        else:
            entries.append([tid, 1, off, n])
    d = bytearray(); _enc_varint(len(entries), d)
    last = 0
    for e in entries:
        _enc_varint(e[0] - last, d); last = e[0]
    for e in entries: _enc_varint(e[1], d)
    for e in entries: _enc_varint(e[3], d)
    for i, e in enumerate(entries):
        prev = entries[i - 1] if i else None
        _enc_varint(0 if prev and e[2] == prev[2] + prev[3] else e[2] + 1, d)
    root = gzip.compress(bytes(d), mtime=0)
    meta = like.get('meta', b'')
    ro, mo = HEADER.size, HEADER.size + len(root)
    do = max(mo + len(meta), like.get('data_off', 0))
    hdr = HEADER.pack(b'PMTiles', 3, ro, len(root), mo, len(meta), do, 0, do, len(blobs),
                      len(ids), len(entries), len(where), 1, 2, 1, tile_type,
                      like['min_zoom'], like['max_zoom'], *like['bounds'], *like['center'])
    with open(path, 'wb') as fh:
        fh.write(hdr + root + meta + bytes(do - mo - len(meta)) + blobs)
    return do + len(blobs)
