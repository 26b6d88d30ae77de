#!/usr/bin/env python3
"""vtz mesh against Delatin (pydelatin) at the same max error, same rasters, same run.

Usage: vs_delatin.py VTZ_BINARY RASTER.f32 ... [--pct 10,3,1]

Each raster is a ../shared/corpus NAME.f32 + NAME.json. For each bound (percent of the
value range) prints vertices, triangles, measured max error and RMSE of each mesh (both
checked here over every valid sample by linear interpolation over the mesh's triangles),
and wall seconds (vtz: the CLI process including reading the file; Delatin: the call).
"""
import json, subprocess, sys, time, os, tempfile
import numpy as np
from pydelatin import Delatin


def raster(path):
    meta = json.load(open(path[:-4] + ".json"))
    a = np.fromfile(path, dtype="<f4").reshape(meta["height"], meta["width"]).astype(np.float64)
    nd = meta.get("nodata")
    valid = np.isfinite(a) if nd is None else (a != nd) & np.isfinite(a)
    return a, valid


def tin_errors(a, valid, verts, tris):
    """Max and RMS |linear − sample| over valid samples; verts (x=col, y=row, z)."""
    h, w = a.shape
    seen = np.zeros_like(valid)
    est = np.full(a.shape, np.nan)
    for t in tris:
        p = verts[t]
        x0, x1 = int(np.floor(p[:, 0].min())), int(np.ceil(p[:, 0].max()))
        y0, y1 = int(np.floor(p[:, 1].min())), int(np.ceil(p[:, 1].max()))
        xs, ys = np.meshgrid(np.arange(max(x0, 0), min(x1, w - 1) + 1), np.arange(max(y0, 0), min(y1, h - 1) + 1))
        d = (p[1, 0] - p[0, 0]) * (p[2, 1] - p[0, 1]) - (p[2, 0] - p[0, 0]) * (p[1, 1] - p[0, 1])
        if d == 0:
            continue
        l1 = ((p[1, 0] - xs) * (p[2, 1] - ys) - (p[2, 0] - xs) * (p[1, 1] - ys)) / d
        l2 = ((p[2, 0] - xs) * (p[0, 1] - ys) - (p[0, 0] - xs) * (p[2, 1] - ys)) / d
        l3 = 1 - l1 - l2
        inside = (l1 >= -1e-9) & (l2 >= -1e-9) & (l3 >= -1e-9)
        z = l1 * p[0, 2] + l2 * p[1, 2] + l3 * p[2, 2]
        est[ys[inside], xs[inside]] = z[inside]
    e = np.abs(est - a)[valid]
    e = e[np.isfinite(e)]
    return float(e.max()), float(np.sqrt((e ** 2).mean())), int(e.size)


def read_ply(path):
    with open(path, "rb") as f:
        header = []
        while True:
            line = f.readline().decode().strip()
            header.append(line)
            if line == "end_header":
                break
        nv = int([l for l in header if l.startswith("element vertex")][0].split()[-1])
        nf = int([l for l in header if l.startswith("element face")][0].split()[-1])
        fmt = [l for l in header if l.startswith("format")][0]
        props = [l.split()[-1] for l in header if l.startswith("property") and "list" not in l]
        if "ascii" in fmt:
            v = np.array([list(map(float, f.readline().split()))[:3] for _ in range(nv)])
            t = np.array([list(map(int, f.readline().split()))[1:4] for _ in range(nf)])
        else:
            types = [l.split()[1] for l in header if l.startswith("property") and "list" not in l]
            dt = np.dtype([(n, {"float": "<f4", "double": "<f8"}.get(ty, "<f4")) for n, ty in zip(props, types)])
            vv = np.frombuffer(f.read(dt.itemsize * nv), dtype=dt)
            v = np.stack([vv["x"], vv["y"], vv["z"]], axis=1).astype(np.float64)
            ft = np.dtype([("n", "u1"), ("i", "<u4", 3)])
            t = np.frombuffer(f.read(ft.itemsize * nf), dtype=ft)["i"].astype(np.int64)
    return v, t


def main():
    args = sys.argv[1:]
    pct = [10.0, 3.0, 1.0]
    if "--pct" in args:
        i = args.index("--pct")
        pct = [float(x) for x in args[i + 1].split(",")]
        del args[i : i + 2]
    vtz, files = args[0], args[1:]
    print("| raster | bound (% of range) | vtz vertices | Delatin vertices | vtz ÷ Delatin | vtz max / RMSE | Delatin max / RMSE | vtz s | Delatin s |")
    print("|---|--:|--:|--:|--:|--:|--:|--:|--:|")
    for path in files:
        a, valid = raster(path)
        rng = float(a[valid].max() - a[valid].min())
        name = os.path.basename(path)[:-4]
        for p in pct:
            bound = rng * p / 100
            with tempfile.TemporaryDirectory() as d:
                out = os.path.join(d, "m.ply")
                t0 = time.perf_counter()
                subprocess.run([vtz, "mesh", path, "-o", out, "--max-error", str(bound), "-q"], check=True)
                tv = time.perf_counter() - t0
                v, t = read_ply(out)
            h, w = a.shape
            # Local coordinates are ground units per sample: back to sample units (the
            # raster's corners are vertices, so the extent is (w − 1) × (h − 1) samples).
            sx = v[:, 0].max() / (w - 1)
            sy = v[:, 1].max() / (h - 1)
            v = v.copy()
            v[:, 0] = np.round(v[:, 0] / sx)
            v[:, 1] = np.round(v[:, 1] / sy)
            vv = np.stack([v[:, 0], (h - 1) - v[:, 1], v[:, 2]], axis=1)
            vmax, vrmse, n = tin_errors(a, valid, vv, t)
            filled = np.where(valid, a, np.nanmean(np.where(valid, a, np.nan))).astype(np.float32)
            t0 = time.perf_counter()
            tin = Delatin(filled, max_error=bound)
            td = time.perf_counter() - t0
            dv = np.asarray(tin.vertices, dtype=np.float64)
            dv[:, 1] = (h - 1) - dv[:, 1]  # Delatin's y points north
            dt = np.asarray(tin.triangles, dtype=np.int64)
            dmax, drmse, _ = tin_errors(a, valid, dv, dt)
            print(f"| {name} | {p:g} | {len(v)} | {len(dv)} | {len(v) / len(dv):.2f} | {vmax:.2f} / {vrmse:.2f} | {dmax:.2f} / {drmse:.2f} | {tv:.2f} | {td:.2f} |", flush=True)


main()
