#!/usr/bin/env python3
# Requires (Python 3.11, the venv /work/venv): numpy==2.4.6, tifffile==2026.3.3,
# imagecodecs==2026.3.6 (PNG decoding; tifffile also uses it for Deflate when present).
"""Benchmark inputs for the tiling work (issue 12), built from ../shared/corpus.

Usage: make_inputs.py OUTDIR [--corpus DIR] [--mosaic-size N] [--mosaic-name NAME]
                            [--anchor topleft|bottomright] [--only all|srtm1|mosaic]

Writes into OUTDIR (large: ~1.5 GB with the default 20000² mosaic; keep it out of the repo,
e.g. /work/bigdata/tiles):

  srtm1_full.f32/.json/.tif   the full 3600×3600 SRTM1 tile N45E013 (corpus extra/
                              srtm1_N45E013_full.png, metres = code − 32768, code 0 = nodata,
                              which the tile does not use), as raw little-endian float32 +
                              corpus-style sidecar, and as an int16 Deflate GeoTIFF
                              (EPSG:4326, pixel-is-point, cell centre of (0,0) = 13E 46N).
  srtm1_crop{600,1200,2400}.* top-left crops of it (--anchor bottomright: bottom-right),
                              same three files each, georeferenced to where they sit.
  mosaic20k.tif               N×N int16 samples (N = --mosaic-size, default 20000) from the
                              corpus's four SRTM3 1201² tiles, one per quadrant (NW White
                              Mountains, NE Gabon, SW Kauai, SE Kattegat). Inside a quadrant
                              the tile repeats mirrored (flipped horizontally in odd tile
                              columns, vertically in odd tile rows, step 1200 so the shared
                              edge sample is written once), so every tile border matches
                              exactly; the only seams are the two quadrant boundaries at N/2.
                              Tiled 256×256, Deflate + horizontal predictor, GDAL_NODATA
                              -32768 (Kauai's and Gabon's voids), EPSG:4326 pixel-is-area,
                              3" pixels, upper-left corner 0E 60N (a made-up placement).
                              Written tile row by tile row from an iterator: Python never
                              holds more than one row of 256×256 tiles (~10 MB at 20000).
  MANIFEST.json               name, bytes and sha256 of every file written.

The output is deterministic (no timestamps; the same bytes for the same package versions).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from pathlib import Path

import imagecodecs
import numpy as np
import tifffile

NODATA = -32768
SRTM1_PIXEL = 1.0 / 3600.0
SRTM3_PIXEL = 1.0 / 1200.0
CROPS = (600, 1200, 2400)
MOSAIC_TILE = 256
# Quadrant sources of the mosaic: (NW, NE, SW, SE).
MOSAIC_SOURCES = (
    "srtm3_N44W072_white_mountains",
    "srtm3_N00E010_gabon",
    "srtm3_N22W160_kauai",
    "srtm3_N57E011_kattegat",
)
MOSAIC_ORIGIN = (0.0, 60.0)  # upper-left corner, lon/lat (pixel-is-area)


def geokeys(raster_type: int) -> list[int]:
    """GeoKeyDirectory for EPSG:4326 (raster_type 1 = PixelIsArea, 2 = PixelIsPoint)."""
    keys = [
        (1024, 0, 1, 2),  # GTModelTypeGeoKey = ModelTypeGeographic
        (1025, 0, 1, raster_type),  # GTRasterTypeGeoKey
        (2048, 0, 1, 4326),  # GeographicTypeGeoKey = WGS 84
        (2054, 0, 1, 9102),  # GeogAngularUnitsGeoKey = degree
    ]
    out = [1, 1, 0, len(keys)]
    for k in keys:
        out.extend(k)
    return out


def geotiff_tags(origin_lon: float, origin_lat: float, pixel: float, raster_type: int):
    """tifffile extratags: ModelPixelScale, ModelTiepoint, GeoKeyDirectory, GDAL_NODATA."""
    return [
        (33550, "d", 3, (pixel, pixel, 0.0), True),
        (33922, "d", 6, (0.0, 0.0, 0.0, origin_lon, origin_lat, 0.0), True),
        (34735, "H", len(geokeys(raster_type)), tuple(geokeys(raster_type)), True),
        (42113, "s", 0, str(NODATA), True),
    ]


def write_int16_tif(path: Path, a: np.ndarray, tags) -> None:
    """Striped int16 GeoTIFF, Deflate + horizontal predictor (how GDAL users store DEMs)."""
    assert a.dtype == np.int16
    with tifffile.TiffWriter(path, bigtiff=False) as tw:
        tw.write(a, photometric="minisblack", compression="deflate", predictor=True,
                 rowsperstrip=64, metadata=None, software=False, extratags=tags)


def sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(1 << 24):
            h.update(chunk)
    return h.hexdigest()


def srtm1_products(corpus: Path, out: Path, anchor: str, written: list[Path]) -> None:
    png = corpus / "extra" / "srtm1_N45E013_full.png"
    codes = imagecodecs.imread(png)
    if codes.shape != (3600, 3600) or codes.dtype != np.uint16:
        sys.exit(f"{png}: expected a 3600x3600 16-bit PNG, got {codes.shape} {codes.dtype}")
    png_sha = sha256(png)
    metres = codes.astype(np.int32) - 32768
    metres[codes == 0] = NODATA
    z = metres.astype(np.int16)
    for n in CROPS + (3600,):
        name = "srtm1_full" if n == 3600 else f"srtm1_crop{n}"
        o = 0 if anchor == "topleft" else 3600 - n
        a = np.ascontiguousarray(z[o:o + n, o:o + n])
        valid = a != NODATA
        f32 = out / f"{name}.f32"
        a.astype("<f4").tofile(f32)
        what = ("the full tile" if n == 3600 else
                f"{anchor} crop (rows and cols {o}..{o + n - 1} of the 3600x3600 tile)")
        lat, lon = 46.0 - o * SRTM1_PIXEL, 13.0 + o * SRTM1_PIXEL
        meta = {
            "width": n,
            "height": n,
            "source_dtype": "int16 (decoded from the 16-bit grey PNG extra/srtm1_N45E013_full.png: "
                            "elevation = code - 32768, code 0 = missing)",
            "nodata": float(NODATA),
            "dx": SRTM1_PIXEL,
            "dy": SRTM1_PIXEL,
            "units": "degrees (WGS84 lon/lat); elevation metres",
            "origin": f"cell centre of row 0, col 0 = lat {lat!r}, lon {lon!r} (the 3600x3600 "
                      "Demeton tile is the 3601x3601 SRTM GL1 tile N45E013 less its last row and "
                      "column: its cell (0, 0) is centred on 46N 13E)",
            "row_order": "row 0 is the northern (top) edge; row-major, little-endian float32",
            "license": "public domain (NASA SRTM GL1 v3); hosting repo breki/demeton MIT",
            "source": "shared/corpus extra/srtm1_N45E013_full.png (github breki/demeton "
                      "samples/cache/0/N45E013.png), decoded by benches/tiles/make_inputs.py",
            "notes": f"SRTM 1 arc-second (~30 m) void-filled tile N45E013, {what}. "
                     "Benchmark input for the tiling work (issue 12). Sea is mostly exactly 0.",
            "character": "Friulian plain, Julian Prealps, Karst, Gulf of Trieste and northern Istria",
            "stats": {
                "min": float(a[valid].min()),
                "max": float(a[valid].max()),
                "nodata_fraction": round(float(1.0 - valid.mean()), 6),
            },
            "files": [f"{name}.f32", f"{name}.json", f"{name}.tif"],
            "f32_sha256": sha256(f32),
            "original_file": "extra/srtm1_N45E013_full.png",
            "original_sha256": png_sha,
            "original_encoding": "16-bit greyscale PNG, big-endian samples; metres = value - 32768; "
                                 "0 = no data",
        }
        js = out / f"{name}.json"
        js.write_text(json.dumps(meta, indent=2) + "\n")
        tif = out / f"{name}.tif"
        write_int16_tif(tif, a, geotiff_tags(lon, lat, SRTM1_PIXEL, 2))
        written += [f32, js, tif]


def mirror_index(i: np.ndarray) -> np.ndarray:
    """Index into a 1201-sample source axis for mosaic position i: period 2400, reflected."""
    p = i % 2400
    return np.where(p <= 1200, p, 2400 - p)


def mosaic(corpus: Path, out: Path, n: int, name: str, written: list[Path]) -> None:
    srcs = []
    for s in MOSAIC_SOURCES:
        a = np.fromfile(corpus / f"{s}.f32", "<f4").reshape(1201, 1201)
        a16 = a.astype(np.int16)
        if not np.array_equal(a16.astype(np.float32), a):
            sys.exit(f"{s}: not int16-valued")
        srcs.append(a16)
    half = n // 2
    t = MOSAIC_TILE
    ntiles = (n + t - 1) // t

    def tiles():
        for ty in range(ntiles):
            ys = np.arange(ty * t, ty * t + t)
            top = ys < half
            ry = mirror_index(ys)
            for tx in range(ntiles):
                xs = np.arange(tx * t, tx * t + t)
                left = xs < half
                rx = mirror_index(xs)
                tile = np.empty((t, t), np.int16)
                for qi, (rows, cols) in enumerate(((top, left), (top, ~left),
                                                   (~top, left), (~top, ~left))):
                    if rows.any() and cols.any():
                        tile[np.ix_(rows, cols)] = srcs[qi][np.ix_(ry[rows], rx[cols])]
                # Padding beyond the image edge (partial last tiles) is nodata.
                tile[ys >= n, :] = NODATA
                tile[:, xs >= n] = NODATA
                yield tile

    path = out / name
    with tifffile.TiffWriter(path, bigtiff=False) as tw:
        tw.write(tiles(), shape=(n, n), dtype=np.int16, tile=(t, t), photometric="minisblack",
                 compression="deflate", predictor=True, metadata=None, software=False,
                 extratags=geotiff_tags(*MOSAIC_ORIGIN, SRTM3_PIXEL, 1))
    written.append(path)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("outdir", type=Path)
    here = Path(__file__).resolve().parent
    ap.add_argument("--corpus", type=Path, default=here.parents[2] / "shared" / "corpus",
                    help="the shared corpus (default: ../shared/corpus beside the repo)")
    ap.add_argument("--mosaic-size", type=int, default=20000, help="mosaic width = height")
    ap.add_argument("--mosaic-name", default=None, help="default: mosaic20k.tif for 20000, "
                    "else mosaicN.tif")
    ap.add_argument("--anchor", choices=("topleft", "bottomright"), default="topleft",
                    help="where the 600/1200/2400 crops sit in the tile (default topleft: the "
                         "flat Friulian plain, so 1%% of range is < 1.1 m at 600 and 1200; "
                         "bottomright: the Istrian karst and hills)")
    ap.add_argument("--only", choices=("all", "srtm1", "mosaic"), default="all")
    a = ap.parse_args()
    if a.mosaic_size < 2:
        ap.error("--mosaic-size must be at least 2")
    name = a.mosaic_name or ("mosaic20k.tif" if a.mosaic_size == 20000
                             else f"mosaic{a.mosaic_size}.tif")
    a.outdir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    t0 = time.perf_counter()
    if a.only in ("all", "srtm1"):
        srtm1_products(a.corpus, a.outdir, a.anchor, written)
        print(f"srtm1 products: {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    if a.only in ("all", "mosaic"):
        t1 = time.perf_counter()
        mosaic(a.corpus, a.outdir, a.mosaic_size, name, written)
        print(f"mosaic: {time.perf_counter() - t1:.1f} s", file=sys.stderr)
    manifest_path = a.outdir / "MANIFEST.json"
    manifest = {}
    if manifest_path.exists():
        manifest = {e["name"]: e for e in json.loads(manifest_path.read_text())}
    for p in written:
        manifest[p.name] = {"name": p.name, "bytes": p.stat().st_size, "sha256": sha256(p)}
    manifest_path.write_text(json.dumps([manifest[k] for k in sorted(manifest)], indent=1) + "\n")
    wid = max(len(str(p)) for p in written)
    print(f"{'file':<{wid}} {'bytes':>13} {'MB':>9}")
    for p in written:
        s = p.stat().st_size
        print(f"{str(p):<{wid}} {s:>13} {s / 1e6:>9.1f}")
    print(f"total {sum(p.stat().st_size for p in written) / 1e6:.1f} MB in {a.outdir}, "
          f"{time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
