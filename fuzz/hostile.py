#!/usr/bin/env python3
"""Hostile variants of the golden files: header and directory fields edited and the
checksums recomputed (FORMAT.md: CRC-32 of [0, 16+H) and of the directory), so only the
decoder's own checks stand between such a file and an allocation or a loop sized by the
edited header. tests/suite/hostile.rs makes the same edits in Rust and holds every one to a time
and memory budget; make_seeds.py puts them in the fuzz seeds.

    python3 fuzz/hostile.py OUT_DIR        # writes OUT_DIR/<golden>.<edit>.vtz
"""
import glob, os, struct, sys, zlib

MASK, FLAT, PRIVATE = 1, 9, 0x8000


def _dir_at(data):
    """Offset of the (global) directory's section_count."""
    return 20 + struct.unpack_from("<I", data, 12)[0]


def _recrc(data):
    hlen = struct.unpack_from("<I", data, 12)[0]
    struct.pack_into("<I", data, 16 + hlen, zlib.crc32(bytes(data[:16 + hlen])))
    pos = 20 + hlen
    count = struct.unpack_from("<I", data, pos)[0]
    end = pos + 4 + 16 * count
    struct.pack_into("<I", data, end, zlib.crc32(bytes(data[pos:end])))
    return bytes(data)


def edited(data, fields=(), retype=()):
    """`data` with header fields [(offset, struct format, value)] set and the directory
    entries of the types in `retype` made private and not required; checksums recomputed."""
    data = bytearray(data)
    for off, fmt, v in fields:
        struct.pack_into(fmt, data, off, v)
    pos = _dir_at(data)
    count = struct.unpack_from("<I", data, pos)[0]
    for k in range(count):
        at = pos + 4 + 16 * k
        if struct.unpack_from("<H", data, at)[0] in retype:
            struct.pack_into("<HH", data, at, PRIVATE, 0)
    return _recrc(data)


def residual_claims(data, n, band_log2=None):
    """`data` with its residual section's coded count set to n and, for the fast and lane codings
    (codings 2–5), its band size exponent set (a large one makes one band per pass, so the
    stream directory fits any raster size); the section's and header's CRCs recomputed."""
    d = bytearray(data)
    hlen = struct.unpack_from("<I", d, 12)[0]
    pos = _dir_at(d)
    count = struct.unpack_from("<I", d, pos)[0]
    off = pos + 4 + 16 * count + 4
    for k in range(count):
        at = pos + 4 + 16 * k
        kind, _, _, length = struct.unpack_from("<HHIQ", d, at)
        if kind == 6 and length >= 73:
            struct.pack_into("<Q", d, off + 64, n)
            if band_log2 is not None and d[off] in (2, 3, 4, 5):
                d[off + 72 + 20 * d[off + 3]] = band_log2
            struct.pack_into("<I", d, at + 4, zlib.crc32(bytes(d[off:off + length])))
        off += length
    return _recrc(d)


def variants(data):
    """[(name, bytes)]: the hostile edits of one valid file."""
    version = struct.unpack_from("<H", data, 8)[0]
    hlen = struct.unpack_from("<I", data, 12)[0]
    out = []
    if version in (1, 2):
        w, h = struct.unpack_from("<II", data, 16)
        sizes = [(16384, 16384), (4096, 4096), (256, 256), (1 << 28, 1), (1, 1 << 28), (65536, 4096),
                 (2 * w, h), (w, h + 1), (w + 1, h), (max(w - 1, 1), h)]
        for (nw, nh) in sizes:
            f = [(16, "<I", nw), (20, "<I", nh)]
            out.append((f"size{nw}x{nh}", edited(data, f)))
            out.append((f"size{nw}x{nh}.nomask", edited(data, f, (MASK,))))
            out.append((f"size{nw}x{nh}.nomaskflat", edited(data, f, (MASK, FLAT))))
            # The residual section claiming every sample, as one band per pass.
            claim = residual_claims(edited(data, f, (MASK, FLAT)), nw * nh, 30)
            if claim != edited(data, f, (MASK, FLAT)):
                out.append((f"size{nw}x{nh}.residualclaims", claim))
        if version == 2:
            # The tile fields end the header body: tile_width, tile_height, margin, index.
            t = 16 + hlen - 28
            for tw, th in ((16, 16), (w, 16), (16, h)):
                out.append((f"tile{tw}x{th}", edited(data, [(t, "<I", tw), (t + 4, "<I", th)])))
            out.append(("margin", edited(data, [(t + 8, "<I", 1 << 30)])))
    elif version in (4, 5):
        # The tile index follows the header: header fields edited with the header's CRC
        # recomputed (sizes, tile sides, margin, index length and, in version 5, the split,
        # which end the header body), and index entries edited with the index's CRC
        # recomputed (a chunk end of 4 GiB, a huge valid count, the most chunks).
        w, h = struct.unpack_from("<II", data, 16)
        t = 16 + hlen - (20 if version == 5 else 16)
        ilen = struct.unpack_from("<I", data, t + 12)[0]

        def header_only(f):
            d = bytearray(data)
            for off, fmt, v in f:
                struct.pack_into(fmt, d, off, v)
            struct.pack_into("<I", d, 16 + hlen, zlib.crc32(bytes(d[:16 + hlen])))
            return bytes(d)

        def entry(field_at, fmt, v):
            d = bytearray(data)
            at = 20 + hlen + 4  # entry 0
            struct.pack_into(fmt, d, at + field_at, v)
            end = 20 + hlen + ilen - 4
            struct.pack_into("<I", d, end, zlib.crc32(bytes(d[20 + hlen:end])))
            return bytes(d)

        for (nw, nh) in ((16384, 16384), (1 << 28, 1), (1, 1 << 28), (2 * w, h), (w + 1, h)):
            out.append((f"size{nw}x{nh}", header_only([(16, "<I", nw), (20, "<I", nh)])))
        for tw, th in ((16, 16), (w, 16), (16, h)):
            out.append((f"tile{tw}x{th}", header_only([(t, "<I", tw), (t + 4, "<I", th)])))
        out.append(("margin", header_only([(t + 8, "<I", 1 << 30)])))
        for name, v in (("index_max", 0xFFFFFFFF), ("index_small", 8), ("index_plus1", ilen + 1)):
            out.append((name, header_only([(t + 12, "<I", v)])))
        out.append(("chunk_end_max", entry(40, "<I", 0xFFFFFFFF)))
        out.append(("valid_max", entry(8, "<Q", 1 << 62)))
        out.append(("chunks13", entry(4, "<B", 13)))
        if version == 5:
            for v in (0, 12, 13, 0xFFFFFFFF):
                out.append((f"split{v}", header_only([(t + 16, "<I", v)])))
    elif version == 3:
        points, positions = struct.unpack_from("<QQ", data, 16)
        big = 1 << 27
        for name, f in (("points", [(16, "<Q", big)]),
                        ("positions", [(24, "<Q", big)]),
                        ("both", [(16, "<Q", big), (24, "<Q", big)]),
                        ("extent", [(60, "<I", (1 << 24) + 1), (64, "<I", (1 << 24) + 1)]),
                        ("all", [(16, "<Q", big), (24, "<Q", big),
                                 (60, "<I", (1 << 24) + 1), (64, "<I", (1 << 24) + 1)])):
            out.append((name, edited(data, f)))
    return out


if __name__ == "__main__":
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    dest = sys.argv[1]
    os.makedirs(dest, exist_ok=True)
    n = 0
    for p in sorted(glob.glob(os.path.join(root, "tests/golden/*.vtz"))):
        base = os.path.basename(p)[:-4]
        for name, b in variants(open(p, "rb").read()):
            with open(os.path.join(dest, f"{base}.{name}.vtz"), "wb") as f:
                f.write(b)
            n += 1
    print(n, "hostile files in", dest)
