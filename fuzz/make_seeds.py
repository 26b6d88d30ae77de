#!/usr/bin/env python3
"""Seed corpora for the fuzz targets, from the golden files (tests/golden) and small
crops of corpus rasters written by the vtz CLI in every format it reads.

    python3 fuzz/make_seeds.py [path/to/vtz] [OUT]     # writes OUT/<target>/ (default fuzz/corpus)
"""
import os, random, struct, subprocess, sys, tempfile, glob
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import hostile  # noqa: E402  (fuzz/hostile.py: header-edited golden files)

root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
vtz = sys.argv[1] if len(sys.argv) > 1 else os.path.join(root, "target/release/vtz")
out = sys.argv[2] if len(sys.argv) > 2 else os.path.join(root, "fuzz/corpus")
for t in ("container", "sections", "readers", "roundtrip", "points"):
    os.makedirs(os.path.join(out, t), exist_ok=True)

def put(target, name, data):
    with open(os.path.join(out, target, name), "wb") as f:
        f.write(data)

def run(*args):
    # Some combinations are refused on purpose (an .hgt must be square, a percent bound on a
    # flat crop is 0): those seeds are simply left out.
    subprocess.run([vtz, *args], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

def sections_of(data):
    """(header fields, [(kind, flags, payload)]) of a .vtz file."""
    hlen = struct.unpack_from("<I", data, 12)[0]
    pos = 16 + hlen + 4
    count = struct.unpack_from("<I", data, pos)[0]
    pos += 4
    entries = []
    for _ in range(count):
        kind, flags, _crc, length = struct.unpack_from("<HHIQ", data, pos)
        entries.append((kind, flags, length))
        pos += 16
    pos += 4
    secs = []
    for kind, flags, length in entries:
        secs.append((kind, flags, data[pos:pos + length]))
        pos += length
    return secs

METHOD_INDEX = {3: 0, 2: 1, 5: 2, 4: 3, 6: 4}  # section code → registry index (sibson, grid, haar, fis, residual)
TYPE_CODE = {"u8": 0, "i16": 1, "u16": 2, "i32": 3, "f32": 4, "f64": 5}

with tempfile.TemporaryDirectory() as tmp:
    # Raster golden files (versions 1 and 2); the point sets (v3_*) seed the points target.
    vtzs = sorted(p for p in glob.glob(os.path.join(root, "tests/golden/*.vtz"))
                  if not os.path.basename(p).startswith("v3_"))
    # Small files of every method, with and without a mask, from corpus crops.
    srcs = [("kauai", "corpus/srtm3_N22W160_kauai.hgt", "600,500,40,33", "i16"),
            ("bijou", "corpus/nasadem_west_bijou_escarpment_landlab.asc", "10,10,31,17", "f32"),
            ("crater", "corpus/scape_crater.png", "100,100,24,24", "u16")]
    for name, path, win, st in srcs:
        crop = os.path.join(tmp, name + ".tif")
        full = os.path.join(tmp, name + "_full.vtz")
        run("encode", os.path.join(root, path), "-o", full, "--force", "-q")
        run("decode", full, "-o", crop, "--window", win, "--force", "-q")
        for fmt in ("tif", "png", "exr", "asc", "f32", "hgt"):
            p = os.path.join(tmp, f"{name}_out.{fmt}")
            try:
                run("convert", crop, p, "--force", "-q")
            except subprocess.CalledProcessError:
                continue
            pick = {"tif": 0, "png": 1, "exr": 3, "hgt": 4, "asc": 5, "f32": 6}[fmt]
            body = open(p, "rb").read()
            if fmt == "f32":
                js = open(p[:-4] + ".json", "rb").read()
                body = struct.pack("<H", len(js)) + js + body
            put("readers", f"{name}.{fmt}", bytes([pick]) + body)
        for m, bound in (("sibson", "2%"), ("sibson", "1"), ("grid", "0"), ("grid", "1"), ("haar", "3"), ("fis", "5%"),
                         ("residual", "0"), ("residual", "1"), ("residual", "2%"),
                         # effort 9: the compact range-coded codings; 1 the lane coding, 2 the fast one
                         ("residual-e9", "0"), ("residual-e9", "1"), ("residual-e9", "2%"),
                         ("residual-e1", "0"), ("residual-e1", "1"), ("residual-e1", "2%"),
                         ("residual-e2", "0"), ("residual-e2", "2%")):
            p = os.path.join(tmp, f"{name}_{m}_{bound.strip('%')}.vtz")
            args = ["encode", crop, "-o", p, "--method", m.split("-")[0], "--force", "-q"]
            if "-e" in m:
                args += ["--effort", m.split("-e")[1]]
            if bound != "0":
                args += ["--max-error", bound]
            try:
                run(*args)
            except subprocess.CalledProcessError:
                continue
            vtzs.append(p)
    # GDAL's own files (tests/gdal_written): internal mask bands in strips, LZW tiles, PackBits,
    # a COG; a south-up GeoTIFF; an ASCII grid with NODATA_value nan.
    for p in sorted(glob.glob(os.path.join(root, "tests/gdal_written/*.tif"))):
        put("readers", "gdal_" + os.path.basename(p), bytes([0]) + open(p, "rb").read())
    for p in sorted(glob.glob(os.path.join(root, "tests/gdal_written/*.asc"))):
        put("readers", "gdal_" + os.path.basename(p), bytes([5]) + open(p, "rb").read())
    # Lattices as wide as the residual layer takes (whole numbers up to ±2^38, alternating
    # extremes) and wider (f32 noise over ±3e38, mixed signs and magnitudes): every residual
    # coding (efforts 1, 2, 5, 9), lossless and lossy, and `best` (issue 35: overflow).
    wrng = random.Random(38)
    def f32_raster(name, w, h, values):
        path = os.path.join(tmp, name + ".f32")
        with open(path, "wb") as f:
            f.write(struct.pack(f"<{w * h}f", *values))
        with open(path[:-4] + ".json", "w") as f:
            f.write('{"width": %d, "height": %d}' % (w, h))
        return path
    M = 2.0 ** 38
    wide = {
        "alternating": [M if (i + i // 23) % 2 else -M for i in range(23 * 19)],
        "extremes": [wrng.choice((M, -M, 0.0, M / 2, -M / 2)) for _ in range(23 * 19)],
        "f32noise": [wrng.choice((1, -1)) * 10.0 ** wrng.uniform(-30, 38.5) for _ in range(23 * 19)],
        "f32max": [wrng.choice((3.4e38, -3.4e38, 1e-38, -1e-38, 0.0)) for _ in range(23 * 19)],
    }
    for name, values in wide.items():
        src = f32_raster(name, 23, 19, values)
        for m, bound, effort in (("residual", "0", "1"), ("residual", "0", "2"), ("residual", "0", "5"), ("residual", "0", "9"),
                                 ("residual", "1e30", "1"), ("residual", "1e30", "9"),
                                 ("residual", "1000", "5"), ("best", "0", "5"), ("best", "1e35", "5")):
            p = os.path.join(tmp, f"wide_{name}_{m}_{bound}_e{effort}.vtz")
            args = ["encode", src, "-o", p, "--force", "-q", "--effort", effort]
            if m != "best":
                args += ["--method", m]
            if bound != "0":
                args += ["--max-error", bound]
            try:
                run(*args)
            except subprocess.CalledProcessError:
                continue
            vtzs.append(p)
    for p in vtzs:
        data = open(p, "rb").read()
        put("container", os.path.basename(p), data)
        info = subprocess.run([vtz, "info", p, "--json"], check=True, capture_output=True, text=True).stdout
        import json
        j = json.loads(info)
        w, h = j["width"], j["height"]
        if w > 64 or h > 64:
            continue
        st = TYPE_CODE[j["sample_type"]]
        secs = sections_of(data)
        mask = [s for s in secs if s[0] == 1]
        flat = [s for s in secs if s[0] == 9]
        for kind, _flags, payload in secs:
            if kind not in METHOD_INDEX:
                continue
            flags = 2 * (j.get("nodata") is not None) | 4
            head = bytes([METHOD_INDEX[kind]])
            body = b""
            if mask:
                flags |= 1
                body = struct.pack("<H", len(mask[0][2])) + mask[0][2]
            if flat:
                flags |= 8
                body += struct.pack("<H", len(flat[0][2])) + flat[0][2]
            seed = head + bytes([flags]) + struct.pack("<HHB", w - 1, h - 1, st) + body + payload
            put("sections", f"{os.path.basename(p)}.{kind}", seed)
    # Point sets (container version 3) from small synthetic XYZ files: scattered points,
    # points sharing positions with other values, collinear points, two value columns.
    prng = random.Random(3)
    def xyz(name, rows, header=None):
        path = os.path.join(tmp, name + ".xyz")
        with open(path, "w") as f:
            if header:
                f.write(header + "\n")
            for r in rows:
                f.write(" ".join(repr(v) for v in r) + "\n")
        return path
    scattered = [(prng.randrange(400) / 10, prng.randrange(300) / 10,
                  round(50 + prng.uniform(-5, 5), 2)) for _ in range(120)]
    dups = scattered[:60] + [(x, y, round(z + prng.uniform(-2, 2), 2)) for x, y, z in scattered[:30]]
    line = [(i * 0.5, i * 0.25, round(10 + i * 0.1 + prng.uniform(-1, 1), 2)) for i in range(40)]
    line_dups = line + line[:5]
    two = [(x, y, z, prng.randrange(256)) for x, y, z in scattered[:80]]
    tiny = [(0.0, 0.0, 1.0), (1.0, 0.0, 2.0), (0.0, 1.0, 3.0)]
    for name, rows, header, extra in (("scattered", scattered, None, ["--max-error", "0.5"]),
                                      ("scattered_tight", scattered, None, ["--max-error", "0.01"]),
                                      ("dups", dups, None, ["--max-error", "0.2"]),
                                      ("collinear", line, None, ["--max-error", "0.3"]),
                                      ("collinear_dups", line_dups, None, ["--max-error", "0.3"]),
                                      ("two_columns", two, "x y z intensity",
                                       ["--max-error", "0.5", "--max-error-band", "intensity=3"]),
                                      ("tiny", tiny, None, ["--max-error", "0.1"]),
                                      ("single", tiny[:1], None, ["--max-error", "0.1"])):
        src = xyz(name, rows, header)
        p = os.path.join(tmp, f"points_{name}.vtz")
        try:
            run("encode", src, "-o", p, "--force", "-q", *extra)
        except subprocess.CalledProcessError:
            print("no point-set seed", name, file=sys.stderr)
            continue
        put("points", name + ".vtz", open(p, "rb").read())
    for p in glob.glob(os.path.join(root, "tests/golden/v3_*.vtz")):
        put("points", os.path.basename(p), open(p, "rb").read())
    # Hostile headers: every golden file with its size (tile grid, point counts) edited and
    # its mask or flat section made optional, checksums recomputed (fuzz/hostile.py).
    for p in sorted(glob.glob(os.path.join(root, "tests/golden/*.vtz"))):
        base = os.path.basename(p)[:-4]
        target = "points" if base.startswith("v3_") else "container"
        for name, b in hostile.variants(open(p, "rb").read()):
            put(target, f"hostile_{base}.{name}.vtz", b)
    rng = random.Random(1)
    for i in range(16):
        n = rng.randrange(6, 400)
        put("roundtrip", f"random{i}", bytes(rng.randrange(256) for _ in range(n)))
    # "Wide" roundtrip seeds (type byte | 0x80: raw f32/f64 bits, integer codes over the
    # type's range): f32 and f64 over huge magnitudes with mixed signs, the f32 extremes,
    # every integer type's full range; lossless and lossy, efforts 1, 5 and 9.
    def f32b(v):
        return struct.pack("<f", v) + b"\0" * 4
    def f64b(v):
        return struct.pack("<d", v)
    for st, make in ((4, lambda: f32b(rng.choice((1, -1)) * 10.0 ** rng.uniform(-38, 38.5))),
                     (4, lambda: f32b(rng.choice((3.4e38, -3.4e38, 2.0 ** 38, -(2.0 ** 38), 0.0)))),
                     (5, lambda: f64b(rng.choice((1, -1)) * 10.0 ** rng.uniform(-300, 300))),
                     (5, lambda: f64b(rng.choice((1.7e308, -1.7e308, 5e-324, 2.0 ** 62, -(2.0 ** 62))))),
                     (1, lambda: struct.pack("<i", rng.choice((-32767, 32767, 0))) + b"\0" * 4),
                     (3, lambda: struct.pack("<i", rng.choice((-2 ** 31 + 1, 2 ** 31 - 1, 0))) + b"\0" * 4)):
        for k, (bound, effort_scale) in enumerate(((0, 0), (0, 12), (0, 24), (1 + 4 * 60, 0), (3 + 4 * 255, 24))):
            w, h = rng.randrange(4, 24), rng.randrange(4, 24)
            head = bytes([w - 1, h - 1, 0x80 | st, rng.randrange(7), bound % 256, effort_scale + k % 12])
            put("roundtrip", f"wide_t{st}_{k}_{rng.randrange(1 << 16):04x}", head + b"".join(make() for _ in range(w * h)))
print("seeds in", out)
