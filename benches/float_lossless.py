#!/usr/bin/env python3
"""Lossless float32 rasters: bits per sample of vtz against zstd and pcodec (issue 35, item 7).

Rasters: (a) integer metres turned into feet and back, f32(round(m / 0.3048) · 0.3048)
(a lattice of step 0.3048, no decimal or power-of-two one); (b) full-mantissa floats:
an SRTM tile times √2, the same tile bilinearly resampled by ½ pixel (a quarter lattice)
and by a factor 0.77 (no lattice at all); (c) the corpus's float rasters as they are.
Every raster is raw little-endian f32 + a JSON sidecar, as the corpus keeps them.

For each: vtz lossless (`vtz encode X.f32 -o X.vtz`, lossless is the default; decoded
back and compared bit for bit), zstd -19 and -3 of the raw f32 bytes (the zstd CLI), and
pcodec (level 8, the peers harness's setting) of the f32 array. Bits per sample =
8 · bytes / (width · height), nodata samples included (they are in the raw bytes too).

Usage (numpy and pcodec in a venv; the zstd CLI from Debian's zstd):
    python3 -m venv /tmp/pcvenv && /tmp/pcvenv/bin/pip install numpy pcodec
    /tmp/pcvenv/bin/python benches/float_lossless.py --vtz target/ci/vtz \
        [--before /tmp/vtz_before] [--corpus ../shared/corpus] [--md out.md]
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

try:
    import pcodec
except ImportError:  # the table says "—" for pcodec then
    pcodec = None

FLOAT_CORPUS = [
    "ahn3_delft_dsm_50cm",
    "ahn3_delft_dtm_50cm",
    "noaa_montereybay_topobathy",
    "ned1_halfdome_yosemite",
    "terra_elev_vinschgau",
    "mapbox_fuji_terrainrgb",
    "lidar5m_west_bijou_gully_landlab",
    "nasadem_west_bijou_escarpment_landlab",
]


def load(corpus, name):
    meta = json.load(open(os.path.join(corpus, name + ".json")))
    a = np.fromfile(os.path.join(corpus, name + ".f32"), dtype="<f4")
    return a.reshape(meta["height"], meta["width"]), meta.get("nodata")


def write(d, name, a, nodata, dtype="float32"):
    a = np.ascontiguousarray(a, dtype="<f4")
    path = os.path.join(d, name + ".f32")
    a.tofile(path)
    h, w = a.shape
    json.dump({"width": w, "height": h, "source_dtype": dtype, "nodata": nodata},
              open(os.path.join(d, name + ".json"), "w"))
    return path


def feet(m, nodata):
    """f32(round(m / 0.3048) · 0.3048) on the valid samples, computed in f64."""
    m = m.astype(np.float64)
    valid = m != nodata if nodata is not None else np.ones(m.shape, bool)
    out = np.where(valid, np.round(m / 0.3048) * 0.3048, m)
    return out.astype(np.float32)


def resample(m, f):
    """Bilinear resampling of a hole-free raster by factor f (centres aligned), f64 → f32."""
    m = m.astype(np.float64)
    h, w = m.shape
    H, W = int((h - 1) * f), int((w - 1) * f)
    y = np.arange(H) / f
    x = np.arange(W) / f
    y0 = np.minimum(np.floor(y).astype(int), h - 2)
    x0 = np.minimum(np.floor(x).astype(int), w - 2)
    fy = (y - y0)[:, None]
    fx = (x - x0)[None, :]
    a = m[y0][:, x0]
    b = m[y0][:, x0 + 1]
    c = m[y0 + 1][:, x0]
    d = m[y0 + 1][:, x0 + 1]
    return ((a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy).astype(np.float32)


def rasters(corpus, d):
    out = []
    wm, wn = load(corpus, "srtm3_N44W072_white_mountains")
    ka, kn = load(corpus, "srtm3_N22W160_kauai")
    out.append(("a", "white_mountains feet·0.3048", write(d, "feet_white", feet(wm, wn), wn)))
    out.append(("a", "kauai feet·0.3048 (nodata)", write(d, "feet_kauai", feet(ka, kn), kn)))
    wm64 = wm.astype(np.float64)
    out.append(("b", "white_mountains ·√2", write(d, "sqrt2_white", (wm64 * np.sqrt(2.0)).astype(np.float32), None)))
    half = (wm64[:-1, :-1] + wm64[1:, :-1] + wm64[:-1, 1:] + wm64[1:, 1:]) / 4.0
    out.append(("b", "white_mountains ½-pixel bilinear", write(d, "half_white", half.astype(np.float32), None)))
    out.append(("b", "white_mountains ×0.77 bilinear", write(d, "res077_white", resample(wm, 0.77), None)))
    for name in FLOAT_CORPUS:
        p = os.path.join(corpus, name + ".f32")
        if os.path.exists(p):
            out.append(("c", name, p))
    return out


def zstd_bytes(path, level):
    r = subprocess.run(["zstd", f"-{level}", "-c", "-q", path], capture_output=True, check=True)
    return len(r.stdout)


def pcodec_bytes(a):
    if pcodec is None:
        return None
    return len(pcodec.standalone.simple_compress(a.ravel(), pcodec.ChunkConfig(compression_level=8)))


def vtz_bytes(vtz, path, d):
    if vtz is None:
        return None
    out = os.path.join(d, "x.vtz")
    back = os.path.join(d, "x_back.f32")
    subprocess.run([vtz, "encode", path, "-o", out, "--force"], capture_output=True, check=True)
    n = os.path.getsize(out)
    subprocess.run([vtz, "decode", out, "-o", back, "--force"], capture_output=True, check=True)
    src = np.fromfile(path, dtype="<u4")
    got = np.fromfile(back, dtype="<u4")
    if not np.array_equal(src, got):
        raise SystemExit(f"{vtz}: {path} does not decode bit for bit")
    return n


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vtz", default="target/ci/vtz")
    ap.add_argument("--before", help="a vtz binary from before the change, for a 'before' column")
    ap.add_argument("--corpus", default="../shared/corpus")
    ap.add_argument("--md", help="write the table here too")
    args = ap.parse_args()
    if not os.path.isdir(args.corpus):
        raise SystemExit(f"no corpus at {args.corpus}")
    rows = []
    with tempfile.TemporaryDirectory() as d:
        for kind, label, path in rasters(args.corpus, d):
            a = np.fromfile(path, dtype="<f4")
            n = a.size
            bps = lambda b: None if b is None else 8.0 * b / n
            row = (kind, label, n,
                   bps(vtz_bytes(args.before, path, d)),
                   bps(vtz_bytes(args.vtz, path, d)),
                   bps(zstd_bytes(path, 19)),
                   bps(zstd_bytes(path, 3)),
                   bps(pcodec_bytes(a)))
            rows.append(row)
            print(row, file=sys.stderr)
    f = lambda v: "—" if v is None else f"{v:.2f}"
    lines = ["| kind | raster | samples | vtz before | vtz after | zstd -19 | zstd -3 | pcodec | after ÷ min(zstd -19, pcodec) |",
             "|---|---|--:|--:|--:|--:|--:|--:|--:|"]
    for kind, label, n, before, after, z19, z3, pc in rows:
        best = min(v for v in (z19, pc) if v is not None)
        lines.append(f"| {kind} | {label} | {n} | {f(before)} | {f(after)} | {f(z19)} | {f(z3)} | {f(pc)} | "
                     f"{f(after / best if after is not None else None)} |")
    text = "\n".join(lines)
    print(text)
    if args.md:
        open(args.md, "w").write(text + "\n")


if __name__ == "__main__":
    main()
