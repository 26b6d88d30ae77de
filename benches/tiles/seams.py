"""Seams: does the decoded raster's error change character at tile borders?

For a source and its decode (same size; .f32 raw + .json, or GeoTIFF), the error e = decoded −
source, and for every pair of horizontally (vertically) adjacent samples the step
|e[x+1] − e[x]|. Prints the mean and 99th percentile of that step over pairs that straddle a
tile border against pairs inside tiles, and the same for the decoded surface's second
difference (what a hillshade shows as a crease). A seam shows as border values well above the
inside ones.

    python benches/tiles/seams.py SRC DECODED.tif --tile-w 900 --tile-h 900
needs numpy, tifffile (benches/tiles/README.md).
"""
import argparse
import json
import pathlib

import numpy as np
import tifffile


def load(p: pathlib.Path) -> np.ndarray:
    if p.suffix == ".f32":
        j = json.loads(p.with_suffix(".json").read_text())
        return np.fromfile(p, "<f4").reshape(j["height"], j["width"]).astype(np.float64)
    return tifffile.imread(p).astype(np.float64)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("src", type=pathlib.Path)
    ap.add_argument("dec", type=pathlib.Path)
    ap.add_argument("--tile-w", type=int, required=True)
    ap.add_argument("--tile-h", type=int, required=True)
    a = ap.parse_args()
    s, d = load(a.src), load(a.dec)
    e = d - s
    rows = []
    for name, arr in (("error step |Δe|", e), ("decoded 2nd difference |Δ²z|", d)):
        for axis, t in ((1, a.tile_w), (0, a.tile_h)):
            step = np.abs(np.diff(arr, n=1 if arr is e else 2, axis=axis))
            n = step.shape[axis]
            # pair (i, i+1) straddles a border when i+1 is a multiple of t (second
            # differences: any of the three samples on each side of it).
            idx = np.arange(n)
            if arr is e:
                border = (idx + 1) % t == 0
            else:
                border = ((idx + 1) % t == 0) | ((idx + 2) % t == 0)
            take = lambda m: np.compress(m, step, axis=axis)
            b, i = take(border), take(~border)
            rows.append((name, "x" if axis == 1 else "y", b.mean(), np.percentile(b, 99),
                         i.mean(), np.percentile(i, 99)))
    print("| quantity | axis | across borders: mean | p99 | inside tiles: mean | p99 |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r[0]} | {r[1]} | {r[2]:.3f} | {r[3]:.3f} | {r[4]:.3f} | {r[5]:.3f} |")


if __name__ == "__main__":
    main()
