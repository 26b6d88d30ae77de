#!/usr/bin/env python3
"""Bits per point of vtz point sets against lossless baselines.

Setup (once):
    python3 -m venv /tmp/benchvenv
    /tmp/benchvenv/bin/pip install numpy 'laspy[lazrs]' zstandard

Run (from the repository root, after `cargo build --release`):
    /tmp/benchvenv/bin/python benches/points/bits_per_point.py \
        [--vtz target/release/vtz] [--work /tmp/vtz_points_bench] [--quick]

Sets:
  * AHN3 Delft lidar (/work/shared/corpus/points/ahn3_delft_cropped_{1,2}.laz, CC0):
    ground (class 2) of each file and all returns of file 2, x/y/z at the file's
    0.001 m scale, in the file's (scan) order.
  * random samples of corpus DEMs (raw little-endian f32, row 0 north, + JSON):
    uniform random continuous positions inside the grid of cell centres, height by
    bilinear interpolation; and Poisson-disk samples (Bridson) with a radius tuned
    to give about the same count. Positions in the JSON's CRS (degrees here),
    rounded to 1e-7 degree (about 1 cm); heights rounded to 1 mm.

Per set: vtz at several bounds (checked here, independently: decoded points are
matched to input points by their position on the resolution grid, points sharing
a position compared as sorted multisets, max |dz| <= bound asserted), and lossless
baselines at the input precision: gzip -9 / zstd -19 of the XYZ text; gzip -9 /
zstd -19 of quantized binary columns; LAZ (laspy + lazrs, point format 0, only
x/y/z set) in the input order and in sorted order.

vtz is always given --xy-resolution (the set's grid step): its default detection
stops at 1e-6 and would quantize the 1e-7 degree positions (positions_lossless false).

Writes benches/points/results.csv and prints Markdown tables.
"""
import argparse
import csv
import datetime
import gzip
import json
import os
import platform
import re
import statistics
import subprocess
import sys
import time

import numpy as np
import laspy
import zstandard

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
CORPUS = "/work/shared/corpus"
LIDAR = [f"{CORPUS}/points/ahn3_delft_cropped_1.laz", f"{CORPUS}/points/ahn3_delft_cropped_2.laz"]
DEMS = ["srtm3_N44W072_white_mountains", "ned1_halfdome_yosemite"]

ap = argparse.ArgumentParser()
ap.add_argument("--vtz", default=None)
ap.add_argument("--work", default="/tmp/vtz_points_bench")
ap.add_argument("--quick", action="store_true", help="10^5 samples only")
ap.add_argument("--big-bounds", default="1%", help="comma list of bounds for the 10^6 sets")
ap.add_argument("--big-poisson", action="store_true",
                help="also 10^6 Poisson-disk sets (Bridson in numpy: about 3 min each to sample)")
ap.add_argument("--seed", type=int, default=1)
args = ap.parse_args()

VTZ = args.vtz or next(
    p for p in [os.environ.get("VTZ", ""), f"{REPO}/target_h/release/vtz", f"{REPO}/target/release/vtz"]
    if p and os.path.exists(p))
WORK = args.work
os.makedirs(WORK, exist_ok=True)
rng = np.random.default_rng(args.seed)
ROWS = []


def log(*a):
    print(*a, file=sys.stderr, flush=True)


# ---------------------------------------------------------------- point sets
class PSet:
    """Integer positions ix, iy on a grid of step `res` (CRS units), heights iz in mm."""

    def __init__(self, name, ix, iy, iz, res, decimals, note):
        self.name, self.ix, self.iy, self.iz = name, ix.astype(np.int64), iy.astype(np.int64), iz.astype(np.int64)
        self.res, self.decimals, self.note = res, decimals, note
        self.n = len(ix)
        self.xyz = f"{WORK}/{name}.xyz"
        self.text = None

    def write_xyz(self):
        d = self.decimals
        x = self.ix * self.res
        y = self.iy * self.res
        z = self.iz / 1000.0
        lines = [f"{a:.{d}f} {b:.{d}f} {c:.3f}\n" for a, b, c in zip(x.tolist(), y.tolist(), z.tolist())]
        self.text = "".join(lines).encode()
        with open(self.xyz, "wb") as f:
            f.write(self.text)


def lidar_set(path, name, cls):
    las = laspy.read(path)
    h = las.header
    assert np.allclose(h.scales, 0.001) and np.allclose(h.offsets, 0), (h.scales, h.offsets)
    m = np.ones(len(las.X), bool) if cls is None else (np.asarray(las.classification) == cls)
    return PSet(name, np.asarray(las.X)[m], np.asarray(las.Y)[m], np.asarray(las.Z)[m], 0.001, 3,
                "lidar, scan order, 1 mm x/y/z")


def load_dem(name):
    meta = json.load(open(f"{CORPUS}/{name}.json"))
    w, h = meta["width"], meta["height"]
    a = np.fromfile(f"{CORPUS}/{name}.f32", dtype="<f4").reshape(h, w).astype(np.float64)
    nod = meta.get("nodata")
    bad = ~np.isfinite(a)
    if nod is not None:
        bad |= a == nod
    m = re.search(r"lat (-?[\d.]+), lon (-?[\d.]+)", meta.get("origin", ""))
    geo = None
    if m and "dx" in meta:
        geo = dict(lat0=float(m.group(1)), lon0=float(m.group(2)), dx=meta["dx"], dy=meta["dy"])
    return a, bad, geo


def bilinear(a, bad, px, py):
    h, w = a.shape
    x0 = np.clip(np.floor(px).astype(np.int64), 0, w - 2)
    y0 = np.clip(np.floor(py).astype(np.int64), 0, h - 2)
    fx, fy = px - x0, py - y0
    z = (a[y0, x0] * (1 - fx) * (1 - fy) + a[y0, x0 + 1] * fx * (1 - fy)
         + a[y0 + 1, x0] * (1 - fx) * fy + a[y0 + 1, x0 + 1] * fx * fy)
    ok = ~(bad[y0, x0] | bad[y0, x0 + 1] | bad[y0 + 1, x0] | bad[y0 + 1, x0 + 1])
    return z, ok


def bridson(w, h, r, k=30):
    """Bridson's Poisson-disk sampling on [0,w]x[0,h]; the k candidates of one active
    point are tested at once (first valid one accepted), as in the original."""
    cs = r / np.sqrt(2)
    gw, gh = int(np.ceil(w / cs)) + 1, int(np.ceil(h / cs)) + 1
    grid = -np.ones((gh + 4, gw + 4), np.int64)  # 2-cell margin
    pts = np.empty((int(2 * w * h / r ** 2) + 10, 2))
    n = 0

    def add(p):
        nonlocal n
        pts[n] = p
        grid[int(p[1] / cs) + 2, int(p[0] / cs) + 2] = n
        n += 1
        return n - 1

    active = [add(rng.uniform((0, 0), (w, h)))]
    off = np.array([(i, j) for i in range(-2, 3) for j in range(-2, 3)])
    r2 = r * r
    while active:
        ai = int(rng.integers(len(active)))
        p = pts[active[ai]]
        ang = rng.uniform(0, 2 * np.pi, k)
        rad = np.sqrt(rng.uniform(r2, 4 * r2, k))
        c = p + np.stack([rad * np.cos(ang), rad * np.sin(ang)], 1)
        inside = (c[:, 0] >= 0) & (c[:, 0] < w) & (c[:, 1] >= 0) & (c[:, 1] < h)
        c = c[inside]
        found = False
        if len(c):
            gx = (c[:, 0] / cs).astype(np.int64) + 2
            gy = (c[:, 1] / cs).astype(np.int64) + 2
            nb = grid[gy[:, None] + off[None, :, 1], gx[:, None] + off[None, :, 0]]
            q = pts[np.maximum(nb, 0)]
            d2 = ((q - c[:, None, :]) ** 2).sum(-1)
            okc = ((nb < 0) | (d2 >= r2)).all(1)
            idx = np.flatnonzero(okc)
            if len(idx):
                active.append(add(c[idx[0]]))
                found = True
        if not found:
            active[ai] = active[-1]
            active.pop()
    return pts[:n]


def dem_set(dem, kind, n):
    a, bad, geo = load_dem(dem)
    h, w = a.shape
    cache = f"{WORK}/{dem}_{kind}_{n}.npz"
    if os.path.exists(cache):
        d = np.load(cache)
        px, py, secs = d["px"], d["py"], float(d["secs"])
    else:
        t = time.perf_counter()
        if kind == "uniform":
            px = np.empty(0); py = np.empty(0)
            while len(px) < n:
                qx = rng.uniform(0, w - 1, n); qy = rng.uniform(0, h - 1, n)
                _, ok = bilinear(a, bad, qx, qy)
                px = np.concatenate([px, qx[ok]]); py = np.concatenate([py, qy[ok]])
            px, py = px[:n], py[:n]
        else:
            # Bridson (k=30) gave about 0.62 / r^2 points per unit area here
            r = np.sqrt(0.617 * (w - 1) * (h - 1) / n)
            p = bridson(w - 1, h - 1, r)
            px, py = p[:, 0], p[:, 1]
            _, ok = bilinear(a, bad, px, py)
            px, py = px[ok], py[ok]
        secs = time.perf_counter() - t
        np.savez(cache, px=px, py=py, secs=secs)
    z, _ = bilinear(a, bad, px, py)
    iz = np.rint(z * 1000)
    if geo:  # CRS units (degrees): 1e-7 degree ~ 1.1 cm in latitude
        res, dec = 1e-7, 7
        ix = np.rint((geo["lon0"] + px * geo["dx"]) / res)
        iy = np.rint((geo["lat0"] - py * geo["dy"]) / res)
        unit = "degrees, 1e-7 deg"
    else:
        res, dec = 0.01, 2
        ix, iy = np.rint(px / res), np.rint(py / res)
        unit = "pixels, 0.01 px"
    short = dem.split("_", 1)[1] if dem.startswith(("srtm3_", "ned1_")) else dem
    ps = PSet(f"{short}_{kind}_{len(px)}", ix, iy, iz, res, dec,
              f"{kind} sample of {dem} ({unit}, 1 mm z; sampling {secs:.0f} s)")
    ps.zrange = (iz.max() - iz.min()) / 1000
    return ps


# ---------------------------------------------------------------- baselines
def run(cmd, stdin=None):
    return subprocess.run(cmd, input=stdin, stdout=subprocess.PIPE, stderr=subprocess.PIPE, check=True).stdout


def sorted_order(ps):
    return np.lexsort((ps.iz, ps.iy, ps.ix))  # by x, then y


def quantized_binary(ps):
    o = sorted_order(ps)
    cols = []
    for v in (ps.ix[o], ps.iy[o], ps.iz[o]):
        v = v - v.min()
        d = np.diff(v, prepend=0)
        assert np.abs(d).max() < 2 ** 31
        cols.append(d.astype("<i4").tobytes())
    return b"".join(cols)


def laz_bytes(ps, order, path):
    hdr = laspy.LasHeader(point_format=0, version="1.2")
    hdr.scales = np.array([ps.res, ps.res, 0.001])
    hdr.offsets = np.array([ps.ix.min() * ps.res, ps.iy.min() * ps.res, 0.0])
    las = laspy.LasData(hdr)
    las.X = (ps.ix[order] - ps.ix.min()).astype(np.int32)
    las.Y = (ps.iy[order] - ps.iy.min()).astype(np.int32)
    las.Z = ps.iz[order].astype(np.int32)
    las.write(path, laz_backend=laspy.LazBackend.Lazrs)
    back = laspy.read(path)  # lossless check
    assert np.array_equal(np.asarray(back.X), (ps.ix[order] - ps.ix.min()))
    return os.path.getsize(path)


def baselines(ps):
    out = []
    t = time.perf_counter()
    out.append(("gzip -9 XYZ text", len(run(["gzip", "-9", "-c", ps.xyz]))))
    out.append(("zstd -19 XYZ text", len(run(["zstd", "-19", "-c", "-q", "-T1", ps.xyz]))))
    qb = quantized_binary(ps)
    out.append(("gzip -9 quantized binary", len(gzip.compress(qb, 9))))
    out.append(("zstd -19 quantized binary", len(zstandard.ZstdCompressor(level=19).compress(qb))))
    out.append(("LAZ, input order", laz_bytes(ps, np.arange(ps.n), f"{WORK}/{ps.name}_in.laz")))
    out.append(("LAZ, sorted by x, y", laz_bytes(ps, sorted_order(ps), f"{WORK}/{ps.name}_sorted.laz")))
    log(f"  baselines {time.perf_counter() - t:.1f} s")
    for m, b in out:
        ROWS.append(dict(set=ps.name, points=ps.n, method=m, bound="lossless", bound_abs=0, bytes=b,
                         bits_per_point=8 * b / ps.n, lossless=True))


# ---------------------------------------------------------------- vtz
def load_decoded(path):
    d = np.loadtxt(path, dtype=np.float64)
    return d.reshape(-1, 3)


def vtz(ps, bound, runs, extra=()):
    out = f"{WORK}/{ps.name}.vtz"
    dec = f"{WORK}/{ps.name}_dec.xyz"
    mem = f"{WORK}/mem.txt"
    enc_t, dec_t, kb = [], [], []
    for _ in range(runs):
        t = time.perf_counter()
        js = run(["/usr/bin/time", "-f", "%M", "-o", mem, VTZ, "encode", ps.xyz, "-o", out, "-f",
                  "--max-error", bound, "--json", "--xy-resolution", repr(ps.res), *extra])
        enc_t.append(time.perf_counter() - t)
        kb.append(int(open(mem).read().split()[-1]))
        t = time.perf_counter()
        run([VTZ, "decode", out, "-o", dec, "-f", "-q"])
        dec_t.append(time.perf_counter() - t)
    j = json.loads(js)
    col = j["columns"][0]
    E = col["bound"]
    if bound.endswith("%"):
        mine = float(bound[:-1]) / 100 * ps.zrange
        assert abs(mine - E) <= 1e-9 * max(1, E), (mine, E)
    assert j["points"] == ps.n and j["positions_lossless"], j
    assert os.path.getsize(out) == j["bytes"]
    # independent check: match by position on the resolution grid, sorted multisets per position
    d = load_decoded(dec)
    assert len(d) == ps.n, (len(d), ps.n)
    dx = np.rint(d[:, 0] / ps.res).astype(np.int64)
    dy = np.rint(d[:, 1] / ps.res).astype(np.int64)
    oi = np.lexsort((ps.iz, ps.iy, ps.ix))
    zin = ps.iz[oi] / 1000.0
    od = np.lexsort((d[:, 2], dy, dx))
    assert np.array_equal(ps.ix[oi], dx[od]) and np.array_equal(ps.iy[oi], dy[od]), "positions differ"
    err = np.abs(d[od, 2] - zin)
    maxe = float(err.max())
    rmse = float(np.sqrt((err ** 2).mean()))
    ok = maxe <= E
    if not ok:
        log(f"!!! BOUND VIOLATION {ps.name} bound {bound} ({E}) max {maxe}: "
            f"{VTZ} encode {ps.xyz} -o {out} --max-error {bound} {' '.join(extra)}")
    ROWS.append(dict(set=ps.name, points=ps.n, method="vtz" + (" " + " ".join(extra) if extra else ""),
                     bound=bound, bound_abs=E, bytes=j["bytes"], bits_per_point=8 * j["bytes"] / ps.n,
                     sites=j["sites"], position_bytes=j["position_bytes"], site_bytes=j["site_bytes"],
                     enc_s=statistics.median(enc_t), dec_s=statistics.median(dec_t), runs=runs,
                     max_err=maxe, vtz_max_err=col["max_error"], rmse=rmse, bound_ok=ok,
                     peak_rss_kb=max(kb), lossless=False))
    log(f"  vtz {bound:>8}: {8 * j['bytes'] / ps.n:7.3f} b/pt  sites {j['sites']:>8}  enc {statistics.median(enc_t):6.2f} s"
        f"  dec {statistics.median(dec_t):5.2f} s  max {maxe:.6g} <= {E:.6g} {ok}  {max(kb) / 1024:.0f} MiB")


def bench(ps, bounds, runs):
    log(f"{ps.name}: {ps.n} points, runs {runs}")
    ps.write_xyz()
    if not hasattr(ps, "zrange"):
        ps.zrange = (ps.iz.max() - ps.iz.min()) / 1000
    for b in bounds:
        vtz(ps, b, runs)
    baselines(ps)


# ---------------------------------------------------------------- raster vs Delatin
def raster_rows():
    """vtz raster encode beside the peers' Delatin numbers (same DEM, same % bound)."""
    src = "/work/shared/tools/peers/results/rd_fbm_corpus.csv"
    peers = {}
    for r in csv.DictReader(open(src)):
        if r["codec"] == "delatin":
            peers[(r["raster"], r["target"])] = r
    out = []
    for dem in DEMS:
        meta = json.load(open(f"{CORPUS}/{dem}.json"))
        n = meta["width"] * meta["height"]
        for pct in ("0.1%", "1%"):
            js = json.loads(run([VTZ, "encode", f"{CORPUS}/{dem}.f32", "-o", f"{WORK}/r.vtz", "-f",
                                 "--max-error", pct, "--json"]))
            p = peers.get((dem, pct))
            out.append(dict(raster=dem, samples=n, bound=pct, vtz_bps=8 * js["bytes"] / n,
                            vtz_max=js.get("max_error"),
                            delatin_bps=float(p["bps"]) if p else None,
                            delatin_max=float(p["max_err"]) if p else None))
    return src, out


# ---------------------------------------------------------------- main
def fmt(v, d=3):
    return "" if v is None or v == "" else (f"{v:.{d}f}" if isinstance(v, float) else str(v))


def main():
    t0 = time.perf_counter()
    date = datetime.date.today().isoformat()
    log(f"vtz {VTZ}; work {WORK}")
    sets = []
    lidar_b = ["0.0005", "0.01", "0.05", "0.2"]
    sets.append((lidar_set(LIDAR[0], "ahn3_1_ground", 2), lidar_b, 3))
    sets.append((lidar_set(LIDAR[1], "ahn3_2_ground", 2), lidar_b, 3))
    sets.append((lidar_set(LIDAR[1], "ahn3_2_all", None), lidar_b, 3))
    dem_b = ["0.0005", "0.1%", "1%"]
    for n in ([10 ** 5] if args.quick else [10 ** 5, 10 ** 6]):
        for dem in DEMS:
            for kind in ("uniform", "poisson"):
                if n == 10 ** 6 and kind == "poisson" and not args.big_poisson:
                    continue
                big = n >= 10 ** 6
                log(f"sampling {dem} {kind} {n}")
                sets.append((dem_set(dem, kind, n), args.big_bounds.split(",") if big else dem_b, 1 if big else 3))
    for ps, b, r in sets:
        bench(ps, b, r)
    # vtz on the .laz itself with --class 2 must give the same file as on the XYZ text
    laz_check = []
    for i, name in ((0, "ahn3_1_ground"), (1, "ahn3_2_ground")):
        js = json.loads(run([VTZ, "encode", LIDAR[i], "--class", "2", "-o", f"{WORK}/c.vtz", "-f",
                             "--max-error", "0.05", "--json"]))
        mine = next(r for r in ROWS if r["set"] == name and r["bound"] == "0.05")
        laz_check.append((name, js["bytes"], mine["bytes"], js["points"]))
    src, rr = raster_rows()

    keys = ["set", "points", "method", "bound", "bound_abs", "bytes", "bits_per_point", "sites",
            "position_bytes", "site_bytes", "enc_s", "dec_s", "runs", "max_err", "vtz_max_err", "rmse",
            "bound_ok", "peak_rss_kb", "lossless"]
    with open(f"{HERE}/results.csv", "w", newline="") as f:
        w = csv.DictWriter(f, keys)
        w.writeheader()
        for r in ROWS:
            w.writerow({k: r.get(k, "") for k in keys})

    print(f"Measured {date} on {platform.node()} ({os.cpu_count()} shared cores), {VTZ}; "
          f"script run {time.perf_counter() - t0:.0f} s.\n")
    print("| set | points | method | bound (m) | bytes | bits/point | sites | pos. bits/pt | enc s | dec s | runs | max err (checked) | RMSE |")
    print("|---|--:|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|")
    for r in ROWS:
        lossless = r["lossless"]
        print(f"| {r['set']} | {r['points']} | {r['method']} | "
              f"{'lossless' if lossless else (r['bound'] if not r['bound'].endswith('%') else r['bound'] + ' = ' + fmt(r['bound_abs'], 4))} | "
              f"{r['bytes']} | {r['bits_per_point']:.2f} | {fmt(r.get('sites'))} | "
              f"{fmt(8 * r['position_bytes'] / r['points'], 2) if 'position_bytes' in r else ''} | "
              f"{fmt(r.get('enc_s'), 2)} | {fmt(r.get('dec_s'), 2)} | {fmt(r.get('runs'))} | "
              f"{'0' if lossless else fmt(r['max_err'], 5)} | {'0' if lossless else fmt(r['rmse'], 5)} |")
    print("\nPeak encoder memory (max RSS, /usr/bin/time -f %M), sets of >= 10^6 points:\n")
    print("| set | bound | peak RSS MiB | bytes/point |")
    print("|---|--:|--:|--:|")
    for r in ROWS:
        if not r["lossless"] and r["points"] >= 10 ** 6 * 0.9:
            print(f"| {r['set']} | {r['bound']} | {r['peak_rss_kb'] / 1024:.0f} | {r['peak_rss_kb'] * 1024 / r['points']:.0f} |")
    print(f"\nvtz raster encode vs Delatin (peers, {src}), bits per grid sample:\n")
    print("| raster | samples | bound | vtz raster bps | Delatin bps | Delatin max err |")
    print("|---|--:|--:|--:|--:|--:|")
    for r in rr:
        print(f"| {r['raster']} | {r['samples']} | {r['bound']} | {r['vtz_bps']:.3f} | "
              f"{fmt(r['delatin_bps']) or 'not in peers'} | {fmt(r['delatin_max'])} |")
    print("\nvtz on the .laz with --class 2 vs on the XYZ text (0.05 m):",
          "; ".join(f"{a}: {b} vs {c} bytes ({d} points)" for a, b, c, d in laz_check))
    bad = [r for r in ROWS if r.get("bound_ok") is False]
    print(f"\nbound violations: {len(bad)}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
