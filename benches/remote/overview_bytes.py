"""Bytes an overview read of a version-4 or -5 .vtz fetches, from its tile index alone
(spec/FORMAT.md, "Version 4", "Version 5"): overview K of a tile with c chunks reads chunks 0 ..= max(0,
c − 1 − K), i.e. the prefix that ends at that chunk's end; a tile of one chunk (a method
without coarse levels) is read whole. Prints, per file, the tiles by chunk count and
method, and the share of the file overviews 3, 4 and 5 read (the 20 000² mosaic's 1024²
overview is K = 4).

    python3 benches/remote/overview_bytes.py FILE.vtz...
"""
import collections
import os
import struct
import sys

for f in sys.argv[1:]:
    with open(f, "rb") as fh:
        fixed = fh.read(16)
        version, hlen = struct.unpack_from("<H", fixed, 8)[0], struct.unpack_from("<I", fixed, 12)[0]
        body = fh.read(hlen)  # the header body: width, height, …, then the tile fields
        w, h = struct.unpack_from("<II", body, 0)
        fields = 20 if version == 5 else 16  # version 5 adds the split
        tw, th, _, ilen = struct.unpack_from("<IIII", body, hlen - fields)
        fh.seek(20 + hlen)
        idx = fh.read(ilen)
    tiles = struct.unpack_from("<I", idx, 0)[0]
    total = os.path.getsize(f)
    reads = {3: 0, 4: 0, 5: 0}
    chunks, methods = collections.Counter(), collections.Counter()
    p = 4
    for _ in range(tiles):
        method, c = struct.unpack_from("<H", idx, p)[0], idx[p + 4]
        ends = [struct.unpack_from("<I", idx, p + 40 + 8 * j)[0] for j in range(c)]
        chunks[c] += 1
        methods[method] += 1
        for k in reads:
            reads[k] += ends[max(0, c - 1 - k)]
        p += 40 + 8 * c
    share = ", ".join(f"K={k}: {100 * v / total:.1f} %" for k, v in reads.items())
    print(f"{f}: {total} bytes, {tiles} tiles; chunks {dict(chunks)}; methods {dict(methods)}; {share}")
